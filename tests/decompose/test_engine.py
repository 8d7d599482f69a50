"""The decomposition engine: exact residual, valid minimal subsets, values and bad input."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from aoc_cli.decompose import DecomposeConfig, decompose
from aoc_cli.decompose.reference import reference_residual
from aoc_cli.errors import AocError


def check_subset(result, beliefs, queries):
    """Invariants of every decomposition: simplex weights, <= d+1 affinely independent rows,
    reconstruction of the projection."""
    d = beliefs.shape[1]
    w = result.weights
    assert (w >= 0).all()
    np.testing.assert_allclose(w.sum(1), 1.0, atol=1e-9)
    assert result.rows.shape[1] <= d + 1
    assert ((result.rows >= 0) == (w > 0)).all()
    for q in range(len(queries)):
        used = result.rows[q] >= 0
        pts = beliefs[result.rows[q, used]].astype(np.float64)
        scale = max(1.0, float(np.abs(pts).max()))
        if used.sum() > 1:
            E = (pts[1:] - pts[0]).T / scale
            assert np.linalg.matrix_rank(E, tol=1e-9) == used.sum() - 1, "supporting rows affinely dependent"
        recon = w[q, used] @ pts
        np.testing.assert_allclose(recon, result.projection[q], atol=1e-6 * scale)
        assert np.isnan(result.distance[q, ~used]).all()
        np.testing.assert_allclose(result.distance[q, used], np.linalg.norm(pts - queries[q], axis=1), rtol=1e-9)


def check_residual(result, beliefs, queries):
    """The residual is the reference QP's optimum (piqp: accurate to ~1e-8 of the neighbourhood
    radius at a vertex, hence the small absolute term) and passes the exact optimality test
    <b_c - y, x> >= <x, x> for x = y* - y and every neighbour c."""
    for q in range(len(queries)):
        nb = result.neighbours[q][result.neighbours[q] >= 0]
        B = beliefs[nb].astype(np.float64)
        ref = reference_residual(B, queries[q])
        scale = float(np.linalg.norm(B - queries[q], axis=1).max())
        assert abs(result.residual[q] - ref) <= 1e-6 * ref + 1e-7 * scale, (q, result.residual[q], ref)
        x = result.projection[q] - queries[q]
        # optimal to the solver's stopping rule (gap <= 1e-10 ||x||^2 + 1e-15 scale^2, minnorm.py):
        # every neighbour passes <p, x> >= <x, x> up to 1e-9 scale^2 (the final projection is
        # step 3's, recomputed from its weights)
        gap = x @ x - (B - queries[q]) @ x
        assert (gap <= 1e-9 * scale**2).all(), "projection is not the nearest hull point"
        assert abs(np.linalg.norm(result.projection[q] - queries[q]) - result.residual[q]) <= 1e-9 * scale + 1e-12


@pytest.mark.parametrize("d", [2, 3, 5, 8, 16, 32])
def test_residual_equals_reference_qp_inside_on_boundary_and_outside(d):
    rng = np.random.default_rng(d)
    beliefs = rng.standard_normal((400, d))
    inside = beliefs[rng.integers(0, 400, 6)] * 0.3  # pulled towards the bulk
    directions = rng.standard_normal((6, d))
    radius = np.linalg.norm(beliefs, axis=1).max()
    outside = directions / np.linalg.norm(directions, axis=1, keepdims=True) * (radius + 0.5)
    first = decompose(beliefs, outside)
    # the projection of an outside query lies on the boundary of its neighbours' hull
    boundary = first.projection
    queries = np.vstack([inside, outside, boundary])
    result = decompose(beliefs, queries)
    check_residual(result, beliefs, queries)
    check_subset(result, beliefs, queries)
    assert (result.residual[6:12] > 0).all()


@settings(max_examples=25, deadline=None)
@given(
    d=st.integers(2, 6),
    n=st.integers(1, 60),
    seed=st.integers(0, 2**31 - 1),
    spread=st.sampled_from([0.1, 1.0, 4.0]),
)
def test_weights_are_a_valid_minimal_subset_for_random_corpora(d, n, seed, spread):
    rng = np.random.default_rng(seed)
    beliefs = rng.standard_normal((n, d))
    queries = rng.standard_normal((8, d)) * spread
    result = decompose(beliefs, queries)
    check_subset(result, beliefs, queries)
    check_residual(result, beliefs, queries)


def test_duplicate_rows_give_the_reference_residual_and_independent_support():
    rng = np.random.default_rng(0)
    base = rng.standard_normal((30, 4))
    beliefs = np.vstack([base, base, base[:10]])  # every row at least twice
    queries = np.vstack([base[:5] * 0.5, rng.standard_normal((5, 4)) * 3])
    result = decompose(beliefs, queries)
    check_subset(result, beliefs, queries)
    check_residual(result, beliefs, queries)


@pytest.mark.parametrize("rank", [1, 2])
def test_collinear_and_coplanar_neighbours(rank):
    rng = np.random.default_rng(rank)
    d = 4
    basis = rng.standard_normal((rank, d))
    beliefs = rng.standard_normal((50, rank)) @ basis + 1.0  # on a line / a plane in R^4
    queries = np.vstack([
        beliefs[:4] * 0.5 + beliefs[4:8] * 0.5,  # inside the flat
        rng.standard_normal((4, d)) * 2,  # off the flat
    ])
    result = decompose(beliefs, queries)
    check_subset(result, beliefs, queries)
    check_residual(result, beliefs, queries)
    assert (result.rows >= 0).sum(1).max() <= rank + 1


def test_degenerate_float32_beliefs_on_a_relu_surface_stay_valid():
    """Beliefs of a trained network: float32, on a low-dimensional ReLU surface, duplicated.
    Nearly dependent neighbours must not break the solver; the answers stay valid and agree
    with the reference to the precision the data carries."""
    rng = np.random.default_rng(11)
    basis = rng.standard_normal((2, 20))
    beliefs = np.maximum(rng.standard_normal((3000, 2)) @ basis, 0.0)
    beliefs = np.vstack([beliefs, beliefs[:500]]).astype(np.float32)
    queries = beliefs[rng.integers(0, 3000, 60)] + 0.01 * rng.standard_normal((60, 20)) * (rng.random((60, 1)) < 0.5)
    queries = np.maximum(queries, 0.0)
    result = decompose(beliefs, queries)
    check_subset(result, beliefs.astype(np.float64), queries)
    for q in range(len(queries)):
        B = beliefs[result.neighbours[q]].astype(np.float64)
        scale = float(np.linalg.norm(B - queries[q], axis=1).max())
        ref = reference_residual(B, queries[q])
        assert abs(result.residual[q] - ref) <= 1e-5 * ref + 1e-6 * scale
        x = result.projection[q] - queries[q]
        assert ((B - queries[q]) @ x >= x @ x - 1e-7 * scale**2).all()


def test_k_larger_than_the_corpus_uses_every_row():
    rng = np.random.default_rng(3)
    beliefs = rng.standard_normal((5, 3))
    queries = rng.standard_normal((4, 3))
    result = decompose(beliefs, queries, k=50)
    assert result.neighbours.shape == (4, 5)
    assert (np.sort(result.neighbours, 1) == np.arange(5)).all()
    check_residual(result, beliefs, queries)
    check_subset(result, beliefs, queries)


def test_corpus_of_one_row_puts_all_weight_on_it():
    beliefs = np.array([[1.0, 2.0, 3.0]])
    queries = np.array([[0.0, 0.0, 0.0], [1.0, 2.0, 3.0]])
    result = decompose(beliefs, queries, values=np.array([7.0]))
    assert (result.rows[:, 0] == 0).all() and (result.rows[:, 1:] == -1).all()
    np.testing.assert_allclose(result.weights[:, 0], 1.0)
    np.testing.assert_allclose(result.residual, [np.sqrt(14.0), 0.0])
    np.testing.assert_allclose(result.value, 7.0)


def test_inside_the_hull_the_residual_is_zero_and_the_subset_contains_the_query():
    rng = np.random.default_rng(5)
    for d in (2, 3, 6):
        beliefs = rng.random((500, d))
        queries = 0.3 + 0.4 * rng.random((20, d))
        result = decompose(beliefs, queries)
        inside = result.residual == 0
        assert inside.mean() > 0.5
        assert ((result.rows[inside] >= 0).sum(1) == d + 1).all()
        for q in np.flatnonzero(inside):
            pts = beliefs[result.rows[q]]
            np.testing.assert_allclose(result.weights[q] @ pts, queries[q], atol=1e-9)


@pytest.mark.parametrize("d", [8, 16, 32])
def test_inside_the_hull_in_high_dimension_the_support_is_a_full_simplex(d):
    rng = np.random.default_rng(d)
    beliefs = rng.standard_normal((3 * d, d))
    queries = rng.dirichlet(np.ones(3 * d), size=6) @ beliefs  # inside the corpus hull
    result = decompose(beliefs, queries, k=3 * d)
    assert (result.residual == 0).all() and result.fallbacks == 0
    assert ((result.rows >= 0).sum(1) == d + 1).all()
    check_subset(result, beliefs, queries)
    check_residual(result, beliefs, queries)


def test_query_equal_to_a_corpus_belief_puts_the_weight_on_that_row():
    rng = np.random.default_rng(6)
    beliefs = rng.standard_normal((300, 5))
    beliefs[299] = beliefs[7]  # a duplicate of row 7
    picks = np.array([7, 20, 150, 298])
    result = decompose(beliefs, beliefs[picks])
    for q, row in enumerate(picks):
        same = np.all(beliefs[result.rows[q]] == beliefs[row], axis=1) & (result.rows[q] >= 0)
        assert result.weights[q, same].sum() > 1 - 1e-9
    assert np.all(result.residual == 0)


def test_value_is_the_weighted_sum_of_row_values():
    rng = np.random.default_rng(7)
    beliefs = rng.standard_normal((200, 3))
    values = rng.standard_normal(200)
    queries = rng.standard_normal((10, 3))
    result = decompose(beliefs, queries, values=values)
    expected = (result.weights * np.where(result.rows >= 0, values[result.rows], 0.0)).sum(1)
    np.testing.assert_allclose(result.value, expected)
    assert decompose(beliefs, queries).value is None


def test_rows_of_one_value_give_exactly_that_value():
    # candidates whose supporting rows share a value must tie exactly (the controller breaks
    # value ties by residual), whatever the rounding of the weights
    rng = np.random.default_rng(17)
    beliefs = rng.standard_normal((200, 4))
    queries = rng.standard_normal((20, 4)) * 0.5
    for v in (-0.1, 0.3, 9.9):
        result = decompose(beliefs, queries, values=np.full(200, v))
        assert (result.weights > 0).sum(1).min() >= 2
        assert (result.value == v).all()


def test_reference_path_agrees_with_the_batched_solver():
    rng = np.random.default_rng(8)
    beliefs = rng.standard_normal((300, 4))
    queries = np.vstack([rng.standard_normal((5, 4)) * 0.3, rng.standard_normal((5, 4)) * 3])
    fast = decompose(beliefs, queries)
    slow = decompose(beliefs, queries, reference=True)
    np.testing.assert_allclose(fast.residual, slow.residual, rtol=1e-6, atol=1e-8)
    check_subset(slow, beliefs, queries)


def test_config_k_and_default_k_is_twice_d_plus_one():
    rng = np.random.default_rng(9)
    beliefs = rng.standard_normal((100, 3))
    queries = rng.standard_normal((2, 3))
    assert decompose(beliefs, queries).neighbours.shape == (2, 8)
    assert decompose(beliefs, queries, config=DecomposeConfig(k=5)).neighbours.shape == (2, 5)
    assert decompose(beliefs, queries, k=2).rows.shape == (2, 2)


def test_empty_batch_returns_empty_arrays():
    beliefs = np.random.default_rng(0).standard_normal((10, 3))
    result = decompose(beliefs, np.zeros((0, 3)))
    assert result.rows.shape == (0, 4) and result.residual.shape == (0,)


@pytest.mark.parametrize(
    "kwargs, message",
    [
        (dict(k=0), "k must be at least 1"),
        (dict(queries=np.zeros((2, 4))), "queries must have shape"),
        (dict(beliefs=np.zeros((0, 3))), "non-empty"),
        (dict(queries=np.array([[np.nan, 0.0, 0.0]])), "NaN"),
        (dict(selection=np.zeros(20, dtype=bool)), "leaves no corpus rows"),
        (dict(values=np.zeros(3)), "one entry per corpus row"),
    ],
)
def test_bad_input_raises_one_line_aoc_error(kwargs, message):
    args = dict(beliefs=np.random.default_rng(0).standard_normal((20, 3)), queries=np.zeros((2, 3)))
    args.update(kwargs)
    with pytest.raises(AocError, match=message) as info:
        decompose(**args)
    assert "\n" not in str(info.value)


def test_lifted_nnls_agrees_with_piqp_inside_outside_and_with_duplicates():
    from aoc_cli.decompose.reference import lifted_nnls_weights, reference_weights

    rng = np.random.default_rng(5)
    for trial in range(40):
        d = int(rng.integers(2, 12))
        B = rng.standard_normal((int(rng.integers(d + 1, 3 * d + 4)), d))
        if trial % 4 == 1:
            B = np.vstack([B, B[:3]])                        # duplicates
        y = [B.mean(0), rng.standard_normal(d) * 3, B[0], 0.5 * (B[0] + B[1])][trial % 4]
        w = lifted_nnls_weights(B, y)
        assert (w >= 0).all() and abs(w.sum() - 1) < 1e-12
        ref = np.linalg.norm(reference_weights(B, y) @ B - y)
        scale = np.linalg.norm(B - y, axis=1).max()
        assert np.linalg.norm(w @ B - y) <= ref + 1e-7 * scale


def test_a_query_where_both_solvers_fail_their_checks_still_gets_its_exact_residual(monkeypatch):
    # Seen on a 100k pendulum corpus: a query inside its neighbours' hull up to rounding; the
    # compiled Wolfe loop could not certify optimality and piqp stalled at every tolerance,
    # which ended the episode. The engine now falls back to NNLS instead of raising.
    import aoc_cli.decompose.engine as engine

    def stalled(neighbours, query):
        raise RuntimeError("piqp found no solution of the corpus-residual QP")

    real = engine.min_norm_point

    def uncertified(P, valid, **kw):
        out = real(P, valid, **kw)
        out.ok[:] = False
        return out

    monkeypatch.setattr(engine, "reference_weights", stalled)
    monkeypatch.setattr(engine, "min_norm_point", uncertified)
    rng = np.random.default_rng(11)
    beliefs = rng.standard_normal((300, 6))
    queries = np.vstack([beliefs[:40].mean(0), rng.standard_normal(6) * 4, beliefs[7]])
    result = decompose(beliefs, queries, k=14)
    monkeypatch.undo()
    check_subset(result, beliefs, queries)
    check_residual(result, beliefs, queries)


@pytest.mark.parametrize("rank", [2, 3])
def test_float32_beliefs_on_a_relu_surface_need_no_fallback(rank):
    """Step 2's compiled loop certifies every query on a trained belief's kind of corpus (the
    previous loop sent one or two of these 100 queries to piqp: nearly affinely dependent
    neighbours), and its residual is never above the reference path's (piqp + Caratheodory)."""
    rng = np.random.default_rng(12)
    basis = rng.standard_normal((rank, 20))
    beliefs = np.maximum(rng.standard_normal((3000, rank)) @ basis, 0.0)
    beliefs = np.vstack([beliefs, beliefs[:500]]).astype(np.float32)
    jitter = 0.01 * rng.standard_normal((100, 20)) * (rng.random((100, 1)) < 0.5)
    queries = np.maximum(beliefs[rng.integers(0, 3000, 100)] + jitter, 0.0).astype(np.float32)
    fast = decompose(beliefs, queries)
    assert fast.fallbacks == 0
    slow = decompose(beliefs, queries, reference=True)
    np.testing.assert_array_equal(fast.neighbours, slow.neighbours)
    for q in range(len(queries)):
        B = beliefs[fast.neighbours[q]].astype(np.float64)
        scale = float(np.linalg.norm(B - queries[q], axis=1).max())
        assert fast.residual[q] <= slow.residual[q] + 1e-6 * slow.residual[q] + 1e-7 * scale
    check_subset(fast, beliefs.astype(np.float64), queries.astype(np.float64))


def test_a_full_subset_zeroes_only_a_residual_at_rounding_level(monkeypatch):
    # A step 2 that stops inside the hull (as a fallback QP can) for a query outside it: step 3
    # then finds d + 1 rows around y*, which alone would mean y* = y and r = 0. The residual
    # stays the distance from y to y* (the old rule zeroed it: an outside query read as inside).
    import aoc_cli.decompose.engine as engine

    beliefs = np.array([[0.0, 0.0], [1.0, 0.0], [0.0, 1.0]])
    query = np.array([[0.6, 0.6]])  # outside the triangle (x + y > 1), r* = 0.1 * sqrt(2)

    def inside(B, Y, P, valid, reference, qp_tol):
        return np.where(valid, 1.0 / valid.sum(1, keepdims=True), 0.0), np.arange(len(Y))

    monkeypatch.setattr(engine, "_residual_weights", inside)
    result = decompose(beliefs, query, k=3, values=np.zeros(3))
    np.testing.assert_allclose(result.projection, [[1 / 3, 1 / 3]], atol=1e-12)
    np.testing.assert_allclose(result.residual, [np.hypot(0.6 - 1 / 3, 0.6 - 1 / 3)], rtol=1e-12)
    monkeypatch.undo()
    exact = decompose(beliefs, query, k=3, values=np.zeros(3))
    np.testing.assert_allclose(exact.residual, [0.1 * np.sqrt(2)], rtol=1e-9)
    inner = decompose(beliefs, np.array([[0.2, 0.2]]), k=3, values=np.zeros(3))
    assert inner.residual[0] == 0.0 and (inner.rows[0] >= 0).sum() == 3
