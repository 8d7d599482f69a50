"""Rule 7's default sets (aoc_cli.index.search.denoise, Neighbourhood with no ``nearest``):
every logged row within a radius of the step's denoised observation, checked against a
brute-force reference in numpy, on noisy continuous features with gaps, with clusters and
without."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from aoc_cli.index.search.denoise import (CAP, LEAST, RADIUS, SMOOTH, Denoiser, Sets,
                                          near_row_spread)
from aoc_cli.index.search.masked import brute_force
from aoc_cli.index.search.neighbourhood import Neighbourhood, fitted_values


def _states(noise=0.3, states=6, rows=1200, d=8, gaps=0.0, seed=0):
    """Rows of a few well-separated states seen through Gaussian noise, ``gaps`` of the
    cells unmeasured (held at the row before's value)."""
    rng = np.random.default_rng(seed)
    centres = rng.normal(0, 5, size=(states, d))
    state = rng.integers(0, states, size=rows)
    obs = centres[state] + rng.normal(0, noise, size=(rows, d))
    measured = rng.random(obs.shape) >= gaps
    measured[0] = True
    for i in range(1, rows):
        obs[i, ~measured[i]] = obs[i - 1, ~measured[i]]
    return obs, measured, state, centres


def _reference_sets(hood, obs, measured):
    """(S, n) bool the sets by brute force: the denoised positions (each column's mean over
    the measured cells of the SMOOTH rows nearest by the masked distance), the squared
    distances in the near-row spread, the radius, LEAST and CAP; and the distances."""
    x, m = hood._obs, hood._own
    std = (x - x.mean(0)) / hood.scale
    q = (obs - x.mean(0)) / hood.scale
    qm = np.ones(obs.shape, bool) if measured is None else measured
    d = brute_force(std, m, q, qm) if m is not None else ((q[:, None] - std[None]) ** 2).sum(-1)

    def denoise(d, own):
        near = np.argsort(d, axis=1, kind="stable")[:, :SMOOTH]
        if m is None:
            return x[near].mean(1)
        w = m[near]
        held = w.sum(1)
        return np.where(held > 0, np.where(w, x[near], 0).sum(1) / np.maximum(held, 1), own)
    log_d = brute_force(std, m, std, m) if m is not None else \
        ((std[:, None] - std[None]) ** 2).sum(-1)
    xd = denoise(log_d, x)
    qd = denoise(d, obs)
    centre = xd.mean(0)
    a, b = (xd - centre) / hood.scale, (qd - centre) / hood.scale
    dist = ((b[:, None] - a[None]) ** 2).sum(-1)
    return dist


def test_the_sets_are_the_rows_within_the_radius_of_the_denoised_observation():
    """Against numpy by brute force, on a log with gaps: every row whose squared distance
    from the query's denoised position is clearly inside the radius is in its set, every
    row clearly outside is not (float32 and float64 may part at the boundary)."""
    obs, measured, state, centres = _states(gaps=0.15)
    hood = Neighbourhood(obs, np.zeros(len(obs), np.int64), np.arange(len(obs)), 1,
                         measured=measured)
    assert hood.masked is not None and hood.nearest is None
    rng = np.random.default_rng(3)
    q = centres[state[:40]] + rng.normal(0, 0.3, (40, obs.shape[1]))
    qm = rng.random(q.shape) >= 0.15
    sets = hood.sets(q, qm)
    dist = _reference_sets(hood, q, qm)
    for i in range(len(q)):
        got = set(sets[i].tolist())
        inside = dist[i] < hood.radius * (1 - 1e-4)
        outside = dist[i] > hood.radius * (1 + 1e-4)
        if LEAST <= inside.sum() and (~outside).sum() <= CAP:
            assert set(np.flatnonzero(inside)) <= got
            assert not (got & set(np.flatnonzero(outside)))
        d = dist[i][sets[i]]
        assert np.all(np.diff(d) >= -1e-4 * max(1.0, d.max()))       # nearest first


def test_the_radius_is_a_multiple_of_the_median_distance_to_a_10th_nearest_row():
    obs, measured, state, _ = _states()
    hood = Neighbourhood(obs, np.zeros(len(obs), np.int64), np.arange(len(obs)), 1)
    a = hood.denoised.astype(np.float64)
    d = ((a[:, None] - a[None]) ** 2).sum(-1)
    tenth = np.sort(d, axis=1)[:, 9]                   # the row itself first, at 0
    assert hood.radius == pytest.approx(RADIUS * np.median(tenth), rel=1e-4)


def test_on_noisy_states_a_set_is_pure_and_holds_most_of_its_state():
    """Noise 0.3 about well-separated states in 40 features: the set of an observation holds
    no row of another state and at least 90% of its own state's rows (about 200: twice what
    the 100 nearest could)."""
    obs, measured, state, centres = _states(gaps=0.15, d=40)
    hood = Neighbourhood(obs, np.zeros(len(obs), np.int64), np.arange(len(obs)), 1,
                         measured=measured)
    q = centres + np.random.default_rng(1).normal(0, 0.3, centres.shape)
    sets = hood.sets(q)
    for s in range(len(centres)):
        own = state == s
        assert own[sets[s]].all()
        assert len(sets[s]) >= 0.9 * own.sum() and len(sets[s]) > 150


def test_a_set_holds_at_least_LEAST_and_at_most_CAP_rows():
    """A state repeated exactly more than CAP times reads its CAP nearest rows (the radius is
    above 0: exact repeats are inside), one repeated fewer than LEAST times its LEAST
    nearest. On features without any gathering (uniform), every set lies between the two."""
    rng = np.random.default_rng(0)
    crowd = np.zeros((CAP + 300, 3))
    lone = np.full((LEAST // 2, 3), 40.0)
    far = rng.uniform(-200, 200, (200, 3))
    obs = np.concatenate([crowd, lone, far])
    hood = Neighbourhood(obs, np.zeros(len(obs), np.int64), np.arange(len(obs)), 1)
    sets = hood.sets(np.array([[0.0, 0.0, 0.0], [40.0, 40.0, 40.0]]))
    assert sets.sizes.tolist() == [CAP, LEAST]
    plain = rng.uniform(0, 1, (3000, 5))
    flat = Neighbourhood(plain, np.zeros(3000, np.int64), np.arange(3000), 1)
    sizes = flat.log_sets().sizes
    assert sizes.min() >= LEAST and sizes.max() <= CAP


def test_the_log_sets_are_the_sets_of_its_own_rows():
    obs, measured, *_ = _states(gaps=0.15, rows=600)
    hood = Neighbourhood(obs, np.zeros(len(obs), np.int64), np.arange(len(obs)), 1,
                         measured=measured)
    pick = np.arange(0, 600, 7)
    a, b = hood.log_sets(pick), hood.sets(obs[pick], measured[pick])
    assert [set(a[i].tolist()) for i in range(len(a))] == \
        [set(b[i].tolist()) for i in range(len(b))]


def test_the_near_row_spread_is_of_the_noises_size_not_the_states_spread():
    """Columns of noise 0.1 and 0.5 about states whose centres spread by 5 in every column:
    the near-row spread is of the noise's size (at most 1.5 times its largest), where the
    log's sd reads how far the states lie apart."""
    rng = np.random.default_rng(0)
    centres = rng.normal(0, 5, size=(6, 12))
    state = rng.integers(0, 6, size=3000)
    noise = np.r_[np.full(6, 0.1), np.full(6, 0.5)]
    obs = centres[state] + rng.normal(0, 1, size=(3000, 12)) * noise
    spread = near_row_spread(obs)
    assert np.all(spread < 1.5 * noise.max()) and np.all(spread > noise.min())
    assert np.all(obs.std(0) > 5 * spread)


def test_the_denoiser_averages_the_measured_cells_and_keeps_its_own_where_none():
    x = np.array([[0.0, 10.0], [0.1, 20.0], [0.2, 30.0], [9.0, 0.0]])
    m = np.array([[True, False], [True, True], [True, False], [True, True]])
    den = Denoiser(x, m, np.ones(2), smooth=3)
    got = den(np.array([[0.1, 99.0], [0.1, 5.0]]), np.array([[True, False], [True, True]]))
    # the three nearest rows are 0, 1, 2; of column 1 only row 1 measured it
    assert got[0] == pytest.approx([0.1, 20.0])
    only = Denoiser(x[[0, 2]], m[[0, 2]], np.ones(2), smooth=2)
    assert only(np.array([[0.1, 7.0]]))[0] == pytest.approx([0.1, 7.0])   # none measured


@settings(max_examples=40, deadline=None)
@given(st.lists(st.integers(1, 9), min_size=1, max_size=12), st.integers(0, 10 ** 6))
def test_sets_average_and_join_as_a_loop_does(sizes, seed):
    rng = np.random.default_rng(seed)
    n = 30
    parts = [rng.integers(0, n, size=k) for k in sizes]
    sets = Sets.join([Sets(np.array([0, len(p)]), p) for p in parts])
    values = rng.normal(size=n)
    assert [sets[i].tolist() for i in range(len(sets))] == [p.tolist() for p in parts]
    np.testing.assert_allclose(sets.mean(values), [values[p].mean() for p in parts],
                               rtol=1e-12)
    np.testing.assert_allclose(sets.averaging(n) @ values, [values[p].mean() for p in parts],
                               rtol=1e-12)


def test_fitted_values_over_ragged_sets_average_the_rows_own_action():
    rng = np.random.default_rng(0)
    n = 50
    actions = rng.integers(0, 3, n)
    values = rng.normal(size=n)
    parts = [np.r_[i, rng.choice(np.delete(np.arange(n), i), rng.integers(0, 8),
                                 replace=False)] for i in range(n)]
    sets = Sets.join([Sets(np.array([0, len(p)]), p) for p in parts])
    want = [values[p][actions[p] == actions[i]].mean() for i, p in enumerate(parts)]
    np.testing.assert_allclose(fitted_values(values, actions, sets), want, rtol=1e-12)


@settings(max_examples=40, deadline=None)
@given(st.lists(st.integers(0, 9), min_size=1, max_size=15), st.integers(1, 12))
def test_blocks_cover_the_sets_in_order_within_their_entries(sizes, entries):
    sets = Sets(np.concatenate([[0], np.cumsum(sizes)]).astype(np.int64),
                np.arange(sum(sizes), dtype=np.int32))
    blocks = list(sets.blocks(entries))
    assert [a for a, _ in blocks] == [0] + [b for _, b in blocks[:-1]]
    assert blocks[-1][1] == len(sets)
    for a, b in blocks:
        part = sets.part(a, b)
        assert [part[i].tolist() for i in range(b - a)] == \
            [sets[i].tolist() for i in range(a, b)]
        assert b - a == 1 or part.indptr[-1] <= entries          # one set may exceed it


def test_near_and_fitted_values_are_the_same_worked_in_blocks(monkeypatch):
    """The neighbourhoods read a few entries at a time (tiny blocks) are those read at once:
    the sums run in the same order within a set."""
    import aoc_cli.index.search.denoise as denoise
    obs, measured, state, _ = _states(noise=0.3, rows=600, gaps=0.15)
    rng = np.random.default_rng(1)
    actions = rng.integers(0, 4, len(obs))
    episode = np.arange(len(obs)) // 7
    values = rng.normal(size=len(obs))
    hood = Neighbourhood(obs, actions, episode, 4, values=values, measured=measured)
    sets = hood.log_sets()
    whole, fitted = hood.near(sets), fitted_values(values, actions, sets)
    monkeypatch.setattr(denoise, "ENTRIES", 37)
    assert len(list(sets.blocks())) > 10
    blocked = hood.near(sets)
    np.testing.assert_array_equal(blocked.episodes, whole.episodes)
    np.testing.assert_array_equal(blocked.likely, whole.likely)
    # the same sums in the same order; a few ulp allowed (another CPU's vector paths)
    np.testing.assert_allclose(blocked.mean, whole.mean, rtol=4e-16 * 8, atol=0)
    np.testing.assert_allclose(fitted_values(values, actions, sets), fitted, rtol=4e-16 * 8,
                               atol=0)
    # and both are the loop over each set
    for i in rng.choice(len(sets), 20, replace=False):
        rows = sets[i]
        for a in range(4):
            took = rows[actions[rows] == a]
            assert whole.episodes[i, a] == len(np.unique(episode[took]))
            if len(took):
                assert whole.mean[i, a] == pytest.approx(values[took].mean(), rel=1e-12)
            else:
                assert np.isnan(whole.mean[i, a])
