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
    rows = got.rows.array()
    assert rows.shape == (6, 50) and got.episodes.shape == (6, 4)
    assert (state[rows] == np.arange(6)[:, None]).all()     # noise 0.3: the same state
    assert (got.episodes == _reference_episodes(rows, action, episode, 4)).all()
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


def test_rule_7_keeps_the_likely_action_unless_a_bound_beats_its_own_bound():
    cfg = ControllerConfig()
    residual = np.zeros((4, 4))
    value = np.array([[0.5, 0.9, 0.6, 0.4]] * 4)
    lower = np.array([[0.3, 0.7, 0.5, 0.1],       # 1's bound 0.7 beats kept 0's 0.3: move
                      [0.3, 0.25, 0.2, 0.1],      # none beats 0.3: keep 0
                      [0.3, 0.3, 0.2, 0.1],       # a tie does not move
                      [0.3, -np.inf, 0.35, 0.1]])  # 1 unbounded (no episode): 2 beats 0.3
    kept = np.array([0, 0, 0, 0])
    _, passed, chosen = choose(residual, value, cfg, lower=lower, kept=kept)
    assert chosen.tolist() == [1, 0, 0, 2]
    assert not passed[3, 1] and passed[0].all()   # the bound, not the residual, filters
    # without the rule: the argmax of v_hat
    assert choose(residual, value, cfg)[2].tolist() == [1, 1, 1, 1]


@settings(max_examples=60, deadline=None)
@given(st.integers(0, 2**32 - 1), st.integers(2, 8))
def test_rule_7_moves_exactly_where_a_bound_beats_the_kept_actions_bound(seed, k):
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
    assert (lower[rows, chosen][moved] > lower[rows, kept][moved]).all()
    assert np.isfinite(lower[rows, chosen][moved]).all()
    assert (passed == np.isfinite(lower)).all()
    # the move is to the best bound, and happens exactly where it beats the kept one's
    best = lower.max(1)
    assert (lower[rows, chosen][moved] == best[moved]).all()
    assert (moved == (best > lower[rows, kept])).all()


def test_the_bounds_are_over_the_neighbourhoods_own_rows():
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
    bounds = near.bounds(got)
    z = lower_bound_z(4)
    want = np.where(got.episodes > 0, np.nan_to_num(got.mean, nan=0.0)
                    - z * near.noise / np.sqrt(np.maximum(got.episodes, 1)), -np.inf)
    assert np.allclose(bounds[np.isfinite(want)], want[np.isfinite(want)], rtol=1e-12)
    assert (np.isinf(bounds) == np.isinf(want)).all()
    # values that favour action 3 by far more than the noise: rule 7 moves to it everywhere
    better = values + np.where(action == 3, 5.0, 0.0)
    strong = Neighbourhood(obs, action, episode, 4, values=better, nearest=50)
    at = strong.at(centres)
    _, _, chosen = choose(np.zeros((6, 4)), np.zeros((6, 4)), ControllerConfig(),
                          lower=strong.bounds(at), kept=at.likely)
    assert (chosen == 3).all()
    # values that favour the clinicians' modal action by more than the noise: no move
    worse = values + np.where(action == modal, 1.0, 0.0)
    weak = Neighbourhood(obs, action, episode, 4, values=worse, nearest=50)
    at = weak.at(centres)
    _, _, stay = choose(np.zeros((6, 4)), np.zeros((6, 4)), ControllerConfig(),
                        lower=weak.bounds(at), kept=at.likely)
    assert (stay == at.likely).all() and (at.likely == np.arange(6) % 4).all()


def _two_step_log(episodes=40, cut=(3, 11, 20), gamma=0.9, seed=0):
    """Each episode visits state A then state B (two well-separated points seen through
    noise), rewards drawn per row; the episodes in ``cut`` are censored after A."""
    rng = np.random.default_rng(seed)
    obs, rew, starts = [], [], [0]
    for e in range(episodes):
        steps = 1 if e in cut else 2
        for t in range(steps):
            obs.append(np.full(3, 10.0 * t) + rng.normal(0, 0.1, 3))
            rew.append(rng.normal(1.0 + t, 0.5))
        starts.append(starts[-1] + steps)
    censored = np.array([e in cut for e in range(episodes)])
    return np.array(obs), np.array(rew), np.array(starts), censored, gamma


def test_neighbourhood_values_are_the_tabular_fqe_where_each_neighbourhood_is_its_state():
    """nearest = the rows of a state (A has one row per episode): the iteration's fixed point
    is the behaviour's value table, a censored cut bootstrapping from its own state."""
    from aoc_cli.index.search.neighbourhood import neighbourhood_values
    obs, rew, starts, censored, gamma = _two_step_log()
    first = starts[:-1]
    a_rows = first
    b_rows = np.setdiff1d(np.arange(len(rew)), a_rows)
    values, info = neighbourhood_values(obs, rew, starts, gamma, censored,
                                        nearest=len(a_rows), tol=1e-12)
    assert info["converged"] and info["nearest"] == len(a_rows)
    # B: the last row of every uncensored episode, 37 rows: its neighbourhood is B's 37 rows
    # plus 3 rows of A; solve the two-state fixed point by hand instead
    n_a, n_b = len(a_rows), len(b_rows)
    cut = a_rows[censored]
    go = a_rows[~censored]
    # V_B = mean over B's neighbourhood (B's rows and the nearest A rows): read which
    from aoc_cli.index.search.neighbourhood import Neighbourhood
    hood = Neighbourhood(obs, np.zeros(len(rew), np.int64), np.zeros(len(rew), np.int64), 1,
                         nearest=len(a_rows))
    rows_b = hood.rows(obs[b_rows[:1]])[0]
    extra_a = np.setdiff1d(rows_b, b_rows)
    assert len(extra_a) == n_a - n_b and set(np.setdiff1d(rows_b, extra_a)) == set(b_rows)
    assert set(hood.rows(obs[a_rows[:1]])[0]) == set(a_rows)
    # unknowns V_A, V_B: y_a = r + g V_B (going on), r + g V_A (cut); y_b = r
    # V_A = mean_A y;  V_B = (sum_B r + sum_{extra A} y) / n_a
    m = np.zeros((2, 2))
    c = np.zeros(2)
    m[0, 0] = 1 - gamma * len(cut) / n_a
    m[0, 1] = -gamma * len(go) / n_a
    c[0] = rew[a_rows].sum() / n_a
    extra_go = np.isin(extra_a, go)
    m[1, 0] = -gamma * np.sum(~extra_go) / n_a
    m[1, 1] = 1 - gamma * np.sum(extra_go) / n_a
    c[1] = (rew[b_rows].sum() + rew[extra_a].sum()) / n_a
    v_a, v_b = np.linalg.solve(m, c)
    assert values[b_rows] == pytest.approx(rew[b_rows], abs=1e-9)
    assert values[go] == pytest.approx(rew[go] + gamma * v_b, abs=1e-8)
    assert values[cut] == pytest.approx(rew[cut] + gamma * v_a, abs=1e-8)


def test_fitted_values_average_the_neighbourhood_rows_of_the_rows_own_action():
    from aoc_cli.index.search.neighbourhood import fitted_values
    obs, action, episode, values, *_ = _noisy_log()
    near = Neighbourhood(obs, action, episode, 4, nearest=30)
    rows = near.rows(obs)
    got = fitted_values(values, action, rows)
    for i in range(0, len(obs), 37):
        same = rows[i][action[rows[i]] == action[i]]
        assert i in same                                  # the row itself, at distance 0
        assert got[i] == pytest.approx(values[same].mean(), rel=1e-12)
    # smoother than the values: they average over the state's rows of one action
    assert got.std() < values.std()


def test_a_given_scale_replaces_the_logs_sd_as_each_columns_unit():
    """With ``scale`` the log's sd, the rows are the default's; with a column's unit far above
    its spread, that column no longer tells rows apart: the rows are those of the others."""
    rng = np.random.default_rng(4)
    x = rng.normal(size=(400, 3)) * np.array([1.0, 2.0, 50.0])
    acts, eps = np.zeros(400, np.int64), np.arange(400)
    q = rng.normal(size=(20, 3)) * np.array([1.0, 2.0, 50.0])
    default = Neighbourhood(x, acts, eps, 1, nearest=10)
    same = Neighbourhood(x, acts, eps, 1, nearest=10, scale=x.std(0))
    np.testing.assert_array_equal(default.rows(q), same.rows(q))
    blind = Neighbourhood(x, acts, eps, 1, nearest=10, scale=np.array([1.0, 2.0, 1e9]))
    two = Neighbourhood(x[:, :2], acts, eps, 1, nearest=10, scale=np.array([1.0, 2.0]))
    np.testing.assert_array_equal(np.sort(blind.rows(q), 1), np.sort(two.rows(q[:, :2]), 1))
    assert not np.array_equal(np.sort(default.rows(q), 1), np.sort(blind.rows(q), 1))
