"""Rule 7, do no harm, on noisy continuous features (a small cohort of the icu-cohort test
bed, aoc_cli/envs/icu_cohort.py): the batched decisions of a vectorised rollout are the
controller's one-step decisions, with histories; the clinicians' likely action is kept where
no bound beats it, and the decision's record says so."""

import numpy as np
import pytest

from aoc_cli.belief import BeliefConfig, train_model
from aoc_cli import open_session
from aoc_cli.control.batch import BatchPolicy
from aoc_cli.control.episodes import HistoryBuffer
from aoc_cli.control.records import decision_record
from aoc_cli.index import build_index
from aoc_cli.envs import collect
from aoc_cli.store import Store


@pytest.fixture(scope="module")
def cohort(tmp_path_factory):
    store = Store(tmp_path_factory.mktemp("cohort"))
    data, _ = collect("icu-cohort", episodes=300, seed=0)
    corpus = store.write("c", data)
    train_model(corpus, BeliefConfig(seed=0, threads=1, max_epochs=4, patience=2,
                                     history_length=2), "default")
    build_index(corpus)
    return store


def test_the_batch_policy_decides_as_the_controller_does_step_by_step(cohort):
    session = open_session("c", store=cohort)
    ctl = session.controller
    assert ctl.do_no_harm                      # value mode, discrete, no support penalty
    data = cohort.corpus("c")
    starts = np.asarray(data.episode_starts)
    episodes = [0, 3, 7]
    length = min(int(starts[e + 1] - starts[e]) for e in episodes)
    obs = np.asarray(data.observations)
    policy = BatchPolicy(ctl)
    policy.reset(len(episodes))
    buffers = [HistoryBuffer(2, data.observation_dim, 1, True) for _ in episodes]
    alive = np.arange(len(episodes))
    for t in range(length):
        step = obs[[starts[e] + t for e in episodes]]
        batch = policy(step, alive)
        for j, buf in enumerate(buffers):
            one = ctl.decide(step[j], buf.history())
            if int(one.action) != int(batch[j]):     # only where two paths' rounding ties
                v = one.candidate_values
                assert abs(v[int(one.action)] - v[int(batch[j])]) < 1e-6, (t, j)
            buf.push(step[j], int(one.action), 0.0)


def test_kept_decisions_are_the_likely_action_and_their_record_says_so(cohort):
    session = open_session("c", store=cohort)
    ctl = session.controller
    data = cohort.corpus("c")
    obs = np.asarray(data.observations)[:200]
    near = ctl.neighbourhood.at(obs)
    kept_any = moved_any = False
    for i in range(0, 200, 5):
        d = ctl.decide(obs[i], HistoryBuffer(2, data.observation_dim, 1, True).history())
        assert d.kept == (int(d.action) == int(near.likely[i]))
        if d.kept:
            kept_any = True
            rec = decision_record(d, data, session.index)
            assert rec["rule"] == "kept the clinicians' dose: no better-supported alternative"
        else:
            moved_any = True
            bounds = ctl.neighbourhood.bounds(near)[i]
            assert bounds[int(d.action)] > bounds[int(near.likely[i])]
            assert bounds[int(d.action)] == bounds.max()
    assert kept_any
    off = open_session("c", store=cohort, controller={"do_no_harm": "off"}).controller
    assert not off.do_no_harm
    d = off.decide(obs[0], HistoryBuffer(2, data.observation_dim, 1, True).history())
    assert d.kept is None and int(d.action) == int(np.argmax(
        np.where(d.passed, d.candidate_values, -np.inf)))
    del moved_any


def test_the_contrast_of_a_rule_7_decision_reads_the_bounds(cohort):
    from aoc_cli.explanation.contrast import contrast_record

    session = open_session("c", store=cohort)
    ctl = session.controller
    data = cohort.corpus("c")
    obs = np.asarray(data.observations)[10]
    history = HistoryBuffer(2, data.observation_dim, 1, True).history()
    d = ctl.decide(obs, history)
    rec = contrast_record(ctl, obs, history, d, data, session.index)
    why = rec["why"]
    bounds = ctl.neighbourhood.bounds(ctl.neighbourhood.at(obs[None]))[0]
    assert why["reason"] in ("lower bound", "no nearby stay received it")
    assert why["chosen_bound"] == bounds[d.chosen]
    if why["reason"] == "lower bound":
        assert why["bound"] == bounds[rec["candidate"]] <= bounds[d.chosen]
    else:
        assert not np.isfinite(bounds[rec["candidate"]])
