"""icu-sepsis end to end at CI size: a log of 1,000 clinician episodes, ``aoc train`` and ``aoc
index`` with their defaults, the controller with the task's settings, and the exact value of
its decisions (every live state decided once: a state policy, valued by one linear solve over
the package's tables).

Guards decision quality: AOC must beat the clinicians who wrote the log (0.782) by
:data:`THRESHOLD`, with every decision backed by at most d_b + 1 named rows of named patients.
Sizes: docs/results.md, "icu-sepsis" (the bench at 1k, 10k and 50k episodes).
"""

import numpy as np
import pytest

from aoc_cli.control import ControllerConfig
from aoc_cli.envs import icu_sepsis
from aoc_cli.experiments.sepsis_policies import LIVE, state_policy
from aoc_cli.control import open_session
from aoc_cli.store import Store

EPISODES = 1000
#: The exact survival AOC's decisions must reach (clinicians 0.7818, random 0.7801, their
#: modal dose 0.7868). Measured 0.7953 with the task's defaults (fqe values, cap, support
#: penalty); the return-to-go values of before gave 0.7895.
THRESHOLD = 0.790


@pytest.fixture(scope="module")
def decided(tmp_path_factory):
    from tests.conftest import run_aoc

    root = tmp_path_factory.mktemp("sepsis-store")
    env = {**__import__("os").environ, "AOC_STORE": str(root)}
    for args in (("collect", "icu-sepsis", "--episodes", str(EPISODES), "--name", "log"),
                 ("train", "log"), ("index", "log")):
        code, _out, err = run_aoc(*args, "--format", "json", env=env)
        assert code == 0, (args, err)
    corpus = Store(root).corpus("log")
    session = open_session(corpus, "default", config=ControllerConfig.for_task("icu-sepsis"))
    decisions = []

    def decide(observation, history):
        d = session.controller.decide(observation, history)
        decisions.append(d)
        return d

    tables = icu_sepsis.tables("mean")
    assert session.history_length == 0, "icu-sepsis is Markov in its observation: the task's " \
        "default history length is 0, so AOC's policy is a state policy"
    policy = state_policy(decide, tables)
    return corpus, session, tables, policy, decisions


def test_aoc_beats_the_clinicians_exactly(decided):
    _corpus, _session, tables, policy, _decisions = decided
    value = tables.mdp.value(policy)
    clinicians = tables.mdp.value(tables.clinicians)
    assert value >= THRESHOLD > clinicians, (value, clinicians)


def test_every_decision_is_backed_by_at_most_d_b_plus_one_rows_of_named_patients(decided):
    corpus, session, _tables, _policy, decisions = decided
    assert len(decisions) == LIVE
    ids = corpus.episode_ids
    starts = corpus.episode_starts
    limit = session.model.d_b + 1
    for d in decisions:
        rows = np.asarray(d.support_rows)
        assert 1 <= len(rows) <= limit
        patients = {ids[int(np.searchsorted(starts, r, side="right")) - 1] for r in rows}
        assert all(p.startswith("p") for p in patients)
