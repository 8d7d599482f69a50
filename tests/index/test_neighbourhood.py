"""The log's evidence near an observation (aoc_cli.index.search.neighbourhood) and rule 7, do no
harm (aoc_cli.control.rule.choose with ``lower`` and ``kept``), on noisy continuous features
as a cohort holds them, and on a log whose states repeat exactly."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from aoc_cli.control.config import ControllerConfig
from aoc_cli.control.rule import choose
from aoc_cli.index.search.neighbourhood import Neighbourhood, lower_bound_z


def _noisy_log(noise=0.3, states=6, episodes=300, length=4, n_actions=4, seed=0):
    """Episodes over a few well-separated states seen through Gaussian noise; the behaviour's
    modal action at state s is s % n_actions (taken 70% of the time); values are the state's
    value plus noise of sd 0.2."""
    rng = np.random.default_rng(seed)
    centres = rng.normal(0, 5, size=(states, 8))
    state = rng.integers(0, states, size=episodes * length)
    obs = centres[state] + rng.normal(0, noise, size=(len(state), 8))
    modal = state % n_actions
    action = np.where(rng.random(len(state)) < 0.7, modal, rng.integers(0, n_actions, len(state)))
    episode = np.repeat(np.arange(episodes), length)
    values = state / states + rng.normal(0, 0.2, len(state))
    return obs, action, episode, values, state, centres, modal


def _reference_episodes(rows, actions, episode, n_actions):
    out = np.zeros((len(rows), n_actions), np.int64)
    for q, r in enumerate(rows):
        for a in range(n_actions):
            out[q, a] = len(set(episode[r][actions[r] == a].tolist()))
    return out


def test_the_neighbourhood_counts_distinct_episodes_per_action_and_finds_the_modal_action():
    obs, action, episode, values, state, centres, modal = _noisy_log()
    near = Neighbourhood(obs, action, episode, 4, values=values, nearest=50)
    queries = centres + np.random.default_rng(1).normal(0, 0.3, centres.shape)
    got = near.at(queries)
    assert got.rows.shape == (6, 50) and got.episodes.shape == (6, 4)
    assert (state[got.rows] == np.arange(6)[:, None]).all()     # noise 0.3: the same state
    assert (got.episodes == _reference_episodes(got.rows, action, episode, 4)).all()
    assert (got.likely == np.arange(6) % 4).all()               # the modal action, recovered
    # the noise of one value about its neighbourhood's mean: the 0.2 drawn
    assert near.noise == pytest.approx(0.2, rel=0.1)


def test_an_exact_repeat_log_counts_the_states_own_rows():
    """Where states repeat exactly, the nearest rows at distance 0 are the state's own: the
    count is the exact-repeat support (up to ``nearest``)."""
    obs, action, episode, values, state, centres, _ = _noisy_log(noise=0.0, episodes=40)
    for s in range(6):
        own = state == s
        near = Neighbourhood(obs, action, episode, 4, values=values, nearest=int(own.sum()))
        got = near.at(centres)
        assert set(got.rows[s].tolist()) == set(np.flatnonzero(own).tolist())
        for a in range(4):
            assert got.episodes[s, a] == len(set(episode[own & (action == a)].tolist()))


def test_the_lower_bound_is_the_bonferroni_bound_and_none_without_an_episode():
    obs, action, episode, values, *_ = _noisy_log()
    near = Neighbourhood(obs, action, episode, 4, values=values, nearest=50)
    value = np.array([[0.5, 0.6, 0.7, 0.8]])
    eps = np.array([[4, 9, 0, 1]])
    lower = near.lower(value, eps)
    z = lower_bound_z(4)
    assert z == pytest.approx(2.2414, abs=1e-4)                 # Phi^-1(1 - 0.05 / 4)
    assert lower[0, 0] == pytest.approx(0.5 - z * near.noise / 2, rel=1e-12)
    assert lower[0, 1] == pytest.approx(0.6 - z * near.noise / 3, rel=1e-12)
    assert lower[0, 2] == -np.inf
    assert lower[0, 3] == pytest.approx(0.8 - z * near.noise, rel=1e-12)


def test_rule_7_keeps_the_likely_action_unless_a_bound_beats_its_value():
    cfg = ControllerConfig()
    residual = np.zeros((3, 4))
    value = np.array([[0.5, 0.9, 0.6, 0.4],       # 1's bound 0.7 beats kept 0's value 0.5
                      [0.5, 0.9, 0.6, 0.4],       # 1's bound 0.45 does not: keep 0
                      [0.5, 0.9, 0.6, 0.4]])      # the kept action is the best bound itself
    lower = np.array([[0.3, 0.7, 0.5, 0.1],
                      [0.3, 0.45, 0.2, 0.1],
                      [0.3, 0.2, 0.2, 0.1]])
    kept = np.array([0, 0, 0])
    _, _, chosen = choose(residual, value, cfg, lower=lower, kept=kept)
    assert chosen.tolist() == [1, 0, 0]
    # without the rule: the argmax of v_hat
    assert choose(residual, value, cfg)[2].tolist() == [1, 1, 1]


@settings(max_examples=60, deadline=None)
@given(st.integers(0, 2**32 - 1), st.integers(2, 8))
def test_rule_7_never_takes_an_action_whose_bound_does_not_beat_the_kept_value(seed, k):
    rng = np.random.default_rng(seed)
    s = 20
    value = rng.normal(size=(s, k))
    lower = value - rng.exponential(1.0, size=(s, k))
    lower[rng.random((s, k)) < 0.2] = -np.inf
    residual = rng.exponential(size=(s, k))
    kept = rng.integers(0, k, s)
    _, passed, chosen = choose(residual, value, ControllerConfig(epsilon=0.7), lower=lower,
                               kept=kept)
    rows = np.arange(s)
    moved = chosen != kept
    assert (lower[rows, chosen][moved] > value[rows, kept][moved]).all()
    assert passed[rows, chosen][moved].all()
    # where some passing bound beats the kept value, the rule moves to the best such bound
    best = np.where(passed, lower, -np.inf).max(1)
    # (the kept action's own bound never beats its value: lower <= v_hat)
    assert (moved == (best > value[rows, kept])).all()


def test_the_rows_back_a_move_only_where_their_own_bound_beats_the_likely_actions_mean():
    obs, action, episode, values, state, centres, modal = _noisy_log()
    near = Neighbourhood(obs, action, episode, 4, values=values, nearest=50)
    got = near.at(centres)
    for q in range(len(centres)):
        for a in range(4):
            took = action[got.rows[q]] == a
            if took.any():
                assert got.mean[q, a] == pytest.approx(values[got.rows[q]][took].mean(),
                                                       rel=1e-12)
            else:
                assert np.isnan(got.mean[q, a])
    backed = near.backed(got)
    low = near.lower(np.nan_to_num(got.mean, nan=-np.inf), got.episodes)
    base = got.mean[np.arange(len(centres)), got.likely]
    assert (backed == (low > base[:, None])).all()
    assert not backed[np.arange(len(centres)), got.likely].any()   # never the likely itself
    # values that favour action 3 by far more than the noise: its move is backed
    better = values + np.where(action == 3, 5.0, 0.0)
    strong = Neighbourhood(obs, action, episode, 4, values=better, nearest=50)
    moved = strong.backed(strong.at(centres))
    assert moved[:, 3][np.arange(6) % 4 != 3].all()
