"""Exact what-if (``--without``): a decision re-decided without some corpus rows by a row mask
on the same index equals the decision over a corpus rebuilt without them, and one whose
neighbours were all kept is unchanged bit for bit."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from aoc_cli.control import Controller, open_session
from aoc_cli.explanation.decisions import explain_logged_step
from aoc_cli.explanation.whatif import redecide, removal
from aoc_cli.index import CorpusIndex
from aoc_cli.errors import AocError
from aoc_cli.index.search import BeliefIndex
from tests.control.corpora import corridor_store


@pytest.fixture
def maze(small_maze):
    """A small maze corpus (value mode, continuous actions, tag ``policy``) and its index."""
    return small_maze


@pytest.fixture(scope="module")
def corridor(tmp_path_factory):
    """The corridor corpus: imitation of discrete actions, candidates of each action."""
    return corridor_store(tmp_path_factory.mktemp("whatif") / "store")


def rebuilt(session, keep: np.ndarray) -> Controller:
    """A controller over the corpus rebuilt without the removed rows: the same model, the kept
    rows' beliefs and values, an index of the same kind over them alone."""
    ci, corpus = session.index, session.corpus
    beliefs = np.ascontiguousarray(np.asarray(ci.beliefs)[keep])
    values = None if ci.values is None else np.asarray(ci.values)[keep]
    sub_index = BeliefIndex.build(beliefs, kind=ci.index.kind)
    strata = None if ci.strata is None else ci.strata[keep]
    sub_ci = CorpusIndex(ci.index_id, ci.model, beliefs, values, sub_index, dict(ci.meta),
                         strata)
    episode = corpus.episode_of(np.flatnonzero(keep))
    starts = np.concatenate([[0], np.flatnonzero(np.diff(episode)) + 1, [len(episode)]])
    sub_corpus = SimpleNamespace(
        name=corpus.name, actions=np.asarray(corpus.actions)[keep], discrete=corpus.discrete,
        n_actions=corpus.n_actions, action_space=corpus.action_space, n_rows=int(keep.sum()),
        episode_starts=starts.astype(np.int64))
    return Controller(sub_corpus, sub_ci, session.controller.config)


def logged_query(corpus, row: int, length: int):
    obs = np.asarray(corpus.observations[row], np.float32)
    return obs, corpus.history([row], length)


def neighbour_rows(session, decision, obs, hist) -> np.ndarray:
    """Every corpus row step 1 found for any candidate of ``decision``."""
    model = session.model
    acts = None if model.mode == "imitation" else decision.candidates
    beliefs = model.beliefs(obs[None], acts, hist)
    dec = session.index.decompose(beliefs, k=session.controller.config.k)
    return np.unique(dec.neighbours[dec.neighbours >= 0])


def assert_same_decision(got, want, kept_rows: np.ndarray) -> None:
    """``want`` (over the rebuilt corpus, rows numbered among the kept rows) is ``got``."""
    np.testing.assert_array_equal(np.asarray(got.action), np.asarray(want.action))
    np.testing.assert_array_equal(got.support_rows, kept_rows[want.support_rows])
    np.testing.assert_allclose(got.support_weights, want.support_weights, rtol=1e-12,
                               atol=1e-15)
    np.testing.assert_allclose(got.residual, want.residual, rtol=1e-12, atol=1e-15)
    if want.value is not None:
        np.testing.assert_allclose(got.value, want.value, rtol=1e-12, atol=1e-15)
    if len(want.candidate_values):
        np.testing.assert_allclose(got.candidate_values, want.candidate_values, rtol=1e-12,
                                   atol=1e-15)


@pytest.mark.parametrize("which", ["maze", "corridor"])
def test_a_decision_without_rows_equals_the_decision_over_a_rebuilt_corpus(which, maze,
                                                                          corridor):
    store = maze if which == "maze" else corridor
    corpus = store.corpus(which)
    session = open_session(corpus, seed=3)
    ctl = session.controller
    checked_changed = 0
    for row in (5, 40, 77, 130):
        obs, hist = logged_query(corpus, row, session.history_length)
        decision = ctl.decide(obs, hist)
        # remove the episodes of the decision's three heaviest supporting rows
        episodes = np.unique(corpus.episode_of(decision.support_rows[:3]))
        rem = removal(corpus, without_episodes=[str(e) for e in episodes])
        keep = rem.keep(None)
        after = redecide(ctl, obs, hist, decision, keep)
        want = rebuilt(session, keep)
        ref = want.decompose_candidates(obs, hist, decision.candidates, choose=True) \
            if session.model.mode == "value" else want.decide(obs, hist)
        assert_same_decision(after, ref, np.flatnonzero(keep))
        assert not np.isin(after.support_rows, np.flatnonzero(rem.mask)).any()
        checked_changed += not np.array_equal(after.support_rows, decision.support_rows)
    assert checked_changed > 0  # the removed rows did support these decisions


@pytest.mark.parametrize("which", ["maze", "corridor"])
def test_a_decision_that_used_none_of_the_removed_rows_is_unchanged_bit_for_bit(
        which, maze, corridor):
    store = maze if which == "maze" else corridor
    corpus = store.corpus(which)
    session = open_session(corpus, seed=1)
    row = 50
    obs, hist = logged_query(corpus, row, session.history_length)
    decision = session.controller.decide(obs, hist)
    # the episodes none of whose rows step 1 found for any candidate of this decision
    used = np.unique(corpus.episode_of(neighbour_rows(session, decision, obs, hist)))
    spare = [e for e in range(corpus.n_episodes) if e not in used][:5]
    rem = removal(corpus, without_episodes=[str(e) for e in spare])
    after = redecide(session.controller, obs, hist, decision, rem.keep(None))
    assert np.array_equal(np.asarray(after.action), np.asarray(decision.action))
    assert after.residual == decision.residual and after.value == decision.value
    assert np.array_equal(after.support_rows, decision.support_rows)
    assert np.array_equal(after.support_weights, decision.support_weights)
    assert np.array_equal(after.candidate_values, decision.candidate_values)


def test_explain_reports_unchanged_for_a_removal_far_from_the_query(corridor):
    corpus = corridor.corpus("corridor")
    session = open_session(corpus)
    rec, = explain_logged_step(session, corpus, 0, 3)
    obs, hist = logged_query(corpus, 3, session.history_length)
    used = np.unique(corpus.episode_of(neighbour_rows(
        session, session.controller.decide(obs, hist), obs, hist)))
    spare = [str(e) for e in range(1, corpus.n_episodes) if e not in used][:3]
    rem = removal(corpus, without_episodes=spare)
    rec2, = explain_logged_step(session, corpus, 0, 3, removal=rem)
    w = rec2["what_if"]
    plain = [{k: v for k, v in s.items() if k != "attribution"} for s in rec["support"]]
    assert w["unchanged"] and w["support"] == plain and w["action"] == rec["action"]
    assert w["without"] == {"label": "episodes " + ",".join(spare), "rows": int(rem.rows),
                            "episodes": 3}


def test_evaluate_without_rows_decides_each_step_as_explain_does(corridor):
    from aoc_cli.explanation.whatif import what_if_steps
    from aoc_cli.evaluation.score import score_log

    corpus = corridor.corpus("corridor")
    session = open_session(corpus)
    rem = removal(corpus, without_episodes=[str(e) for e in range(0, 60, 3)])
    _, before = score_log(session, corpus, [])
    summary, after = score_log(session, corpus, [], selection=rem.keep(None))
    w = what_if_steps(before, after, rem, corpus, summary)
    flipped = before.decided != after.decided
    assert w["flipped"] == int(flipped.sum()) and w["steps"] == corpus.n_rows
    assert w["score_change"]["max_abs"] > 0
    # a step of each kind, decided one at a time by explain (own episode left out there too)
    for i in [int(np.flatnonzero(flipped)[0]) if flipped.any() else 0, 7, 200]:
        rec, = explain_logged_step(session, corpus, int(before.episode[i]),
                                   int(before.step[i]), removal=rem)
        assert rec["action"] == int(before.decided[i])
        assert rec["what_if"]["action"] == int(after.decided[i])
        # the beliefs of one step and of a batch differ in float32's last bits
        np.testing.assert_allclose(rec["what_if"]["residual"], after.residual[i], atol=1e-6)


def test_removals_that_cannot_be_made_are_errors(corridor):
    corpus = corridor.corpus("corridor")
    with pytest.raises(AocError, match="no tag"):
        removal(corpus, {"site": ["a"]})
    with pytest.raises(AocError, match="no episode '60'"):
        removal(corpus, without_episodes=["60"])
    with pytest.raises(AocError, match="every row"):
        removal(corpus, without_episodes=[str(e) for e in range(60)])
    assert removal(corpus) is None
