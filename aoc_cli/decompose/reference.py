"""Slow, obviously-correct references: the corpus residual by a general QP solver (piqp through
qpsolvers), Caratheodory reduction, simplex volumes and the brute-force smallest containing hull.

Used by the tests to check the batched engine, by `decompose(..., reference=True)`, and as the
per-problem fallback when the batched solver reports a failure.
"""

from __future__ import annotations

import itertools
import math

import numpy as np
import qpsolvers


def reference_weights(neighbours: np.ndarray, query: np.ndarray) -> np.ndarray:
    """argmin_{w in simplex} ||B^T w - y||^2 by piqp (an interior-point method).

    neighbours: (k, d) beliefs B; query: (d,) y. Returns (k,) weights (not necessarily sparse:
    interior points of an optimal face share the weight; see `caratheodory`).
    """
    B = np.asarray(neighbours, dtype=np.float64)
    y = np.asarray(query, dtype=np.float64)
    k = B.shape[0]
    if k == 1:
        return np.ones(1)
    P = B - y
    scale = max(float(np.sqrt((P**2).sum(1).max())), 1e-300)
    P = P / scale
    G = P @ P.T + 1e-14 * np.eye(k)
    # The tightest tolerances first; near-degenerate neighbourhoods (duplicates, a query
    # almost inside the hull) can stall piqp there, so loosen step by step before giving up.
    w = None
    for eps, gap in ((1e-12, 1e-14), (1e-10, 1e-12), (1e-8, 1e-10)):
        w = qpsolvers.solve_qp(
            G,
            np.zeros(k),
            A=np.ones((1, k)),
            b=np.array([1.0]),
            lb=np.zeros(k),
            solver="piqp",
            eps_abs=eps,
            eps_rel=eps,
            eps_duality_gap_abs=gap,
            eps_duality_gap_rel=gap,
        )
        if w is not None:
            break
    if w is None:
        raise RuntimeError("piqp found no solution of the corpus-residual QP")
    w = np.maximum(np.asarray(w, dtype=np.float64), 0.0)
    return w / w.sum()


def lifted_nnls_weights(neighbours: np.ndarray, query: np.ndarray,
                        lift: float = 1e4) -> np.ndarray:
    """argmin_{w in simplex} ||B^T w - y|| by scipy's NNLS (an active-set method) on the lifted
    system min_{w >= 0} ||[P^T; lift 1^T] w - [0; lift]||, P = (B - y) / max ||b - y||, then
    normalised. A second exact-in-the-limit solver for the rare neighbourhoods where piqp
    stalls at every tolerance (a query inside the hull up to rounding): the sum constraint is
    met to O(residual^2 / lift^2). neighbours: (k, d); query: (d,). Returns (k,) weights."""
    from scipy.optimize import nnls

    B = np.asarray(neighbours, dtype=np.float64)
    P = B - np.asarray(query, dtype=np.float64)
    P = P / max(float(np.sqrt((P**2).sum(1).max())), 1e-300)
    k = B.shape[0]
    A = np.vstack([P.T, np.full((1, k), lift)])
    b = np.concatenate([np.zeros(P.shape[1]), [lift]])
    w, _ = nnls(A, b, maxiter=50 * k)
    if not w.sum() > 0:
        raise RuntimeError("NNLS found no solution of the corpus-residual QP")
    return w / w.sum()


def reference_residual(neighbours: np.ndarray, query: np.ndarray) -> float:
    """min_{w in simplex} ||B^T w - y|| by piqp."""
    w = reference_weights(neighbours, query)
    return float(np.linalg.norm(w @ np.asarray(neighbours, dtype=np.float64) - query))


def caratheodory(
    neighbours: np.ndarray, weights: np.ndarray, tol: float = 1e-7, rank_tol: float = 1e-7
) -> np.ndarray:
    """Reduce a convex combination to at most d + 1 affinely independent points, same point.

    While the support is affinely dependent, move the weights along a null vector v of
    [B_S^T; 1^T] (sum v b = 0, sum v = 0) until one weight reaches zero (Caratheodory).
    Weights below tol * max(w) (an interior-point solver's noise) are dropped first; points
    count as dependent below rank_tol relative singular value (float32 beliefs carry ~1e-7).
    """
    B = np.asarray(neighbours, dtype=np.float64)
    w = np.where(weights > tol * weights.max(), weights, 0.0)
    w = w / w.sum()
    scale = max(float(np.abs(B - w @ B).max()), 1e-300)
    while True:
        S = np.flatnonzero(w > 0)
        A = np.vstack([((B[S] - w @ B) / scale).T, np.ones(S.size)])
        _, sv, vt = np.linalg.svd(A)
        rank = int((sv > rank_tol * sv[0]).sum())
        if rank >= S.size:
            return w
        v = vt[-1]
        if not (v > 1e-15).any():
            v = -v
        pos = v > 1e-15
        ratios = w[S][pos] / v[pos]
        j = int(np.argmin(ratios))
        w[S] = w[S] - ratios[j] * v
        w[S[pos][j]] = 0.0
        w = np.maximum(w, 0.0)
        w[w < 1e-15] = 0.0
        w = w / w.sum()


def simplex_volume(points: np.ndarray) -> float:
    """Volume of the simplex on s points in its own affine dimension s - 1 (Gram determinant)."""
    points = np.asarray(points, dtype=np.float64)
    s = points.shape[0]
    if s <= 1:
        return 1.0
    E = (points[1:] - points[0]).T
    gram = E.T @ E
    return float(math.sqrt(max(np.linalg.det(gram), 0.0)) / math.factorial(s - 1))


def barycentric(points: np.ndarray, target: np.ndarray) -> tuple[np.ndarray, float]:
    """Affine coordinates of target in the affine hull of points (least squares) and the
    distance of target from that affine hull."""
    points = np.asarray(points, dtype=np.float64)
    A = np.vstack([points.T, np.ones(points.shape[0])])
    rhs = np.concatenate([np.asarray(target, dtype=np.float64), [1.0]])
    lam, *_ = np.linalg.lstsq(A, rhs, rcond=None)
    return lam, float(np.linalg.norm(points.T @ lam - target))


def smallest_containing_hull(
    neighbours: np.ndarray, target: np.ndarray, size: int, tol: float = 1e-9
) -> tuple[tuple[int, ...] | None, float]:
    """Brute force: among all `size`-subsets of the neighbours that are affinely independent
    and whose hull contains target, the one of smallest volume (in dimension size - 1).

    Returns (subset indices, volume), or (None, inf) when no subset contains the target.
    """
    B = np.asarray(neighbours, dtype=np.float64)
    scale = max(float(np.abs(B - target).max()), 1e-300)
    best, best_vol = None, math.inf
    for subset in itertools.combinations(range(B.shape[0]), size):
        pts = B[list(subset)]
        vol = simplex_volume(pts)
        if vol <= 1e-12 * scale ** (size - 1) or vol >= best_vol:
            continue
        lam, dist = barycentric(pts, target)
        if lam.min() >= -tol and dist <= tol * scale:
            best, best_vol = subset, vol
    return best, best_vol
