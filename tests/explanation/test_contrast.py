"""The contrast of a decision: the best action not chosen, its own rows, and why it lost."""

from __future__ import annotations

import numpy as np
import pytest

from aoc_cli.control import ControllerConfig
from aoc_cli.control import open_session
from aoc_cli.explanation.decisions import explain_query
from tests.control.corpora import corridor_store
from tests.explanation.test_whatif import logged_query, maze  # noqa: F401 (fixture)


@pytest.fixture(scope="module")
def corridor(tmp_path_factory):
    return corridor_store(tmp_path_factory.mktemp("contrast") / "store")


def test_the_contrast_is_the_best_other_candidate_explained_as_compare_explains_it(maze):
    corpus = maze.corpus("maze")
    reasons = set()
    for epsilon in (0.1, 0.5):
        session = open_session(corpus, config=ControllerConfig(epsilon=epsilon), seed=2)
        for row in (3, 60, 200, 333):
            obs, hist = logged_query(corpus, row, session.history_length)
            rec, = explain_query(session, obs, hist)
            c = rec["contrast"]
            assert c["action"] != rec["action"]
            # the same action explained alone (--compare) gives the same numbers and rows
            alone, = explain_query(session, obs, hist, compare=[c["action"]])
            # (a belief of a batch of K and one alone differ in float32's last bits)
            assert alone["value"] == pytest.approx(c["value"], rel=1e-5)
            assert alone["residual"] == pytest.approx(c["residual"], rel=1e-3, abs=1e-6)
            assert [s["row"] for s in alone["support"]] == [s["row"] for s in c["support"]]
            why = c["why"]
            reasons.add(why["reason"])
            assert why["value_gap"] == pytest.approx(rec["value"] - c["value"], abs=1e-12)
            if why["reason"] == "filtered by epsilon":
                assert not c["passed"] and c["residual"] > why["threshold"]
            else:
                assert c["passed"] and why["reason"] == "lower v_hat" and c["value"] < rec["value"]
    assert reasons == {"filtered by epsilon", "lower v_hat"}


def test_an_explained_given_action_has_no_contrast(maze):
    corpus = maze.corpus("maze")
    session = open_session(corpus)
    obs, hist = logged_query(corpus, 10, session.history_length)
    rec, = explain_query(session, obs, hist, action=[0.5, -0.5])
    assert rec["contrast"] is None


def test_imitation_contrast_is_the_other_action_with_its_rows_of_the_subset(corridor):
    corpus = corridor.corpus("corridor")
    session = open_session(corpus)
    seen_rows = 0
    for row in (0, 30, 61, 100, 250, 400):
        obs, hist = logged_query(corpus, row, session.history_length)
        rec, = explain_query(session, obs, hist)
        c = rec["contrast"]
        assert c["action"] == 1 - rec["action"] and c["why"]["reason"] == "lower score"
        mine = [s for s in rec["support"] if s["action"] == c["action"]]
        assert [s["row"] for s in c["support"]] == [s["row"] for s in mine]
        # its score: the sum over the whole subset of weight x the row's label of that action
        assert c["score"] == pytest.approx(
            sum(s["weight"] * s["label"][c["action"]] for s in rec["support"]), abs=1e-12)
        assert c["score"] == pytest.approx(rec["scores"][c["action"]], abs=1e-12)
        assert c["score"] <= 0.5 + 1e-12
        seen_rows += len(mine)
    assert seen_rows > 0
