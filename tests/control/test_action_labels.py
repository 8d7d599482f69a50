"""A ward log whose treatment is text (`none`, `oxygen`) decides exactly as the same log with
0/1, and explain and evaluate show each action's label beside its code."""

from __future__ import annotations

import csv

import numpy as np
import pytest

from aoc_cli.belief.config import BeliefConfig
from aoc_cli.belief.train import train_model
from aoc_cli.control import ControllerConfig, open_session
from aoc_cli.explanation import explain_logged_step
from aoc_cli.index import build_index
from aoc_cli.envs.ward import read_options, write_csv
from aoc_cli.evaluation.records import step_records
from aoc_cli.evaluation.score import score_log
from aoc_cli.formats import read_dataset
from aoc_cli.store import Store

LABELS = ["none", "oxygen"]


@pytest.fixture(scope="module")
def labelled(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("ward-text")
    steps, static = write_csv(tmp, "ward", 60, 0)
    with open(steps) as fh:
        rows = list(csv.reader(fh))
    col = rows[0].index("act_oxygen")
    for r in rows[1:]:
        r[col] = LABELS[int(float(r[col]))]
    text = tmp / "ward-text.csv"
    with open(text, "w", newline="") as fh:
        csv.writer(fh, lineterminator="\n").writerows(rows)
    numeric = read_dataset(steps, options=read_options(static))
    options = read_options(static)
    options.discrete_actions = False  # the text makes them discrete
    data = read_dataset(text, options=options)
    store = Store(tmp / "store")
    corpus = store.write("ward", data)
    train_model(corpus, BeliefConfig(mode="imitation", history_length=1, hidden=16,
                                     belief_dim=4, max_epochs=2, threads=1, seed=0), "default")
    build_index(corpus, "default")
    return store, numeric


def test_the_text_log_holds_the_numeric_logs_actions(labelled):
    store, numeric = labelled
    corpus = store.corpus("ward")
    assert corpus.action_space["names"] == LABELS
    np.testing.assert_array_equal(corpus.actions, numeric.actions)


def test_explain_shows_the_labels_of_decision_support_and_logged_action(labelled):
    store, _ = labelled
    corpus = store.corpus("ward")
    session = open_session(corpus, "default", config=ControllerConfig())
    rec = explain_logged_step(session, corpus, 3, 2)[0]
    assert rec["action_label"] == LABELS[int(rec["action"])]
    assert rec["logged_action_label"] == LABELS[int(rec["logged_action"])]
    assert rec["support"] and all(s["action_label"] == LABELS[int(s["action"])]
                                  for s in rec["support"])


def test_evaluate_step_records_carry_the_labels(labelled):
    store, _ = labelled
    corpus = store.corpus("ward")
    session = open_session(corpus, "default", config=ControllerConfig())
    _, res = score_log(session, corpus, ["knn"])
    recs = list(step_records(session, corpus, res))
    assert len(recs) == corpus.n_rows
    for rec in recs[:50]:
        assert rec["logged_label"] == LABELS[int(rec["logged"])]
        assert rec["decision_label"] == LABELS[int(rec["decision"])]
        assert rec["knn_decision_label"] == LABELS[int(rec["knn_decision"])]
