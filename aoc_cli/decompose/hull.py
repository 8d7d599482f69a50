"""Step 3 of the decomposition: the minimal corpus subset, by exchanging vertices.

Given the projection y* and a first affinely independent support S (|S| = s <= d + 1) whose
hull contains y* (from step 2), look for the subset of the same size with the smallest volume
whose hull still contains y* (the paper's "minimal hull", Definition "Minimal Hull and Minimal
Corpus Subset").

Which points can enter. If y* lies inside the hull of the neighbours (residual 0, s = d + 1)
every neighbour can. If r > 0, y* is on a face of the neighbours' hull: every subset whose hull
contains y* lies on the supporting hyperplane {b : <b - y*, y* - y> = 0}, and in the affine hull
of S; only neighbours there can enter.

How volumes are compared. The volume of a subset T is measured in its own affine dimension
|T| - 1, by the Gram determinant  vol(T) = sqrt(det(E^T E)) / (|T| - 1)!,  E = [b_t - b_t0].
Subsets are ordered first by size (a hull of fewer points has zero volume in any higher
dimension, so it is smaller), then by that volume. The size is the one step 2 found (points
with weight > 0); only same-size subsets in the same affine hull are compared.

The exchange (a simplex-method pivot). Write the barycentric coordinates of y* in S as lam
(all > 0) and those of a candidate c as beta_c (c = sum_i beta_ic b_i, sum beta = 1). Replacing
vertex i by c keeps y* inside the hull iff i wins the ratio test  i = argmin_{beta_ic > 0}
lam_i / beta_ic, and then multiplies the volume by |beta_ic|. Each round every problem takes
the candidate with the smallest such factor, if it is below 1, and pivots its tableau
(beta for all neighbours, as in the simplex method): no linear system is solved per exchange.

The start. Optionally the lifted linear programme  min sum_c w_c ||b_c - y*||^2  subject to
sum w b = y*, w in the simplex, is first solved by the same pivots (entering column = most
negative reduced cost): its vertex is the Delaunay simplex of the neighbours containing y*
(docs/design.md), a good, local start. The exchange search then shrinks it until no single exchange
helps or the budget is spent. The tableau is built and the final weights solved batched
(numpy); the pivots run per problem in compiled code (numba), each problem stopping when it
is done (a batched round cost the same whether one problem pivoted or all).
"""

from __future__ import annotations

from dataclasses import dataclass

import numba
import numpy as np


def minimal_subset(
    points: np.ndarray,
    valid: np.ndarray,
    weights: np.ndarray,
    offset: np.ndarray,
    lp_start: bool = True,
    budget: int = 64,
    face_tol: float = 1e-9,
) -> tuple[np.ndarray, np.ndarray, int]:
    """Shrink the support of each problem to a small-volume hull containing y*.

    points: (Q, k, d) neighbour beliefs minus the query, p_c = b_c - y.
    valid: (Q, k) which neighbours exist. weights: (Q, k) step-2 weights (support = w > 0).
    offset: (Q, d) y* - y.
    lp_start: first move to the lifted-LP (Delaunay) vertex. budget: exchange pivots at most.
    Returns (weights (Q, k) with the new support, support (Q, k) bool, pivots used).
    """
    d = points.shape[2]
    support = weights > 0
    weights = np.where(support, weights, 0.0)
    scale2 = np.maximum(np.max(np.where(valid, (points**2).sum(-1), 0.0), axis=1), 1e-300)
    candidate = valid & _on_face(points, offset, scale2, face_tol) & ~support
    s = support.sum(1)
    todo = np.flatnonzero((s >= 2) & candidate.any(1))
    if todo.size == 0:
        return weights, support, 0

    # rescale about y* (barycentric coordinates are unchanged) so every system is well scaled
    z = points - offset[:, None, :]  # neighbours relative to y*
    zt = z[todo] / np.sqrt(scale2[todo])[:, None, None]
    tab = _Tableau.build(zt, support[todo], candidate[todo], valid[todo])
    pivots = _pivot_rounds(tab.T, tab.lam, tab.slot_col, tab.in_slot, tab.eligible,
                           (zt**2).sum(-1), 4 * (d + 1) + 16 if lp_start else 0, budget)
    new_w, good = _exact_weights(tab, zt)
    weights = weights.copy()
    support = support.copy()
    weights[todo[good]] = new_w[good]
    support[todo[good]] = new_w[good] > 0
    return weights, support, pivots


def _on_face(
    points: np.ndarray, offset: np.ndarray, scale2: np.ndarray, face_tol: float
) -> np.ndarray:
    """(Q, k) bool: neighbours on the supporting hyperplane {b : <b - y*, y* - y> = 0} (all of
    them when the residual is 0), relative to the squared radius scale2 (Q,)."""
    xx = (offset**2).sum(-1)
    gap = np.abs(np.einsum("qkd,qd->qk", points, offset) - xx[:, None])
    return gap <= face_tol * scale2[:, None]


@dataclass
class _Tableau:
    """The simplex tableau of the n problems with something to exchange, s_max slots each.

    T: (n, s_max, k) barycentric coordinates beta of every neighbour in the current support.
    lam: (n, s_max) those of y*. slot_col: (n, s_max) the neighbour in each slot, -1 if empty.
    in_slot: (n, s_max) real slot (supports smaller than s_max are padded).
    eligible: (n, k) neighbours that may enter (on the face, in the support's affine hull).
    """

    T: np.ndarray
    lam: np.ndarray
    slot_col: np.ndarray
    in_slot: np.ndarray
    eligible: np.ndarray

    @classmethod
    def build(
        cls, zt: np.ndarray, sup: np.ndarray, cand: np.ndarray, valid: np.ndarray
    ) -> _Tableau:
        """zt: (n, k, d) neighbours relative to y*, rescaled; sup, cand, valid: (n, k) bool."""
        k = zt.shape[1]
        s_max = int(sup.sum(1).max())
        order = np.argsort(~sup, axis=1, kind="stable")[:, :s_max]  # support columns first
        in_slot = np.take_along_axis(sup, order, axis=1)  # (n, s_max) real slot?
        Z_S = np.take_along_axis(zt, order[:, :, None], axis=1) * in_slot[:, :, None]
        H = _lifted_gram(Z_S, in_slot)
        rhs = np.einsum("qsd,qkd->qsk", Z_S, zt) + in_slot[:, :, None]
        sol = _solve(H, np.concatenate([rhs, in_slot[:, :, None].astype(float)], axis=2))
        T, lam = np.ascontiguousarray(sol[:, :, :k]), np.ascontiguousarray(sol[:, :, k])
        fit = np.einsum("qsk,qsd->qkd", T, Z_S) - zt
        in_aff = (fit**2).sum(-1) + (T.sum(1) - 1.0) ** 2 <= 1e-14
        return cls(T, lam, np.where(in_slot, order, -1), in_slot, cand & in_aff & valid)


@numba.njit(cache=True, nogil=True)
def _pivot_rounds(T, lam, slot_col, in_slot, eligible, sq, lp_rounds, budget):  # pragma: no cover
    """Pivot every problem of the tableau (T (n, s_max, k), lam (n, s_max), slot_col, in_slot,
    eligible; sq (n, k) the squared norms of the rescaled neighbours), in place, in compiled
    code, each problem on its own (its pivots never depend on the others'):

    1. the Delaunay start, at most lp_rounds pivots: the vertex of the lifted LP
       min sum_c w_c ||b_c - y*||^2 (entering column = most negative reduced cost
       ||z_c||^2 - sum_s ||z_s||^2 beta_sc), the Delaunay simplex of the neighbours containing y*;
    2. the exchange, at most budget pivots: while some eligible column has a pivot element
       |beta_ic| < 1 (it shrinks the volume by that factor), the smallest enters.

    The leaving slot of a column is the ratio test's  argmin_{beta_ic > 0} lam_i / beta_ic.
    Returns the most pivots any problem made in phase 1 plus those of phase 2 (the rounds of
    the batched numpy loops this replaced; their outputs are the same to the bit)."""
    n, s_max, k = T.shape
    leave = np.zeros(k, dtype=np.int64)
    piv = np.zeros(k)
    col = np.zeros(s_max)
    prow = np.zeros(k)
    most_lp = 0
    most_ex = 0
    for q in range(n):
        for phase in range(2):
            rounds = lp_rounds if phase == 0 else budget
            made = 0
            for _ in range(rounds):
                # ratio test: the leaving slot of every entering column and its pivot element
                for c in range(k):
                    best = np.inf
                    i_best = 0
                    for s in range(s_max):
                        if in_slot[q, s] and T[q, s, c] > 1e-12:
                            ratio = lam[q, s] / T[q, s, c]
                            if ratio < best:
                                best = ratio
                                i_best = s
                    leave[c] = i_best
                    piv[c] = T[q, i_best, c]
                enter = 0
                best = np.inf
                if phase == 0:  # most negative reduced cost of the lifted LP
                    for c in range(k):
                        red = 0.0
                        if eligible[q, c] and piv[c] > 1e-9:
                            red = sq[q, c]
                            for s in range(s_max):
                                if in_slot[q, s]:
                                    red -= sq[q, slot_col[q, s]] * T[q, s, c]
                        if red < best:
                            best = red
                            enter = c
                    if not best < -1e-12:
                        break
                else:  # the smallest volume factor |beta_ic| below 1
                    for c in range(k):
                        f = piv[c] if (eligible[q, c] and piv[c] > 1e-9) else np.inf
                        if f < best:
                            best = f
                            enter = c
                    if not best < 1.0 - 1e-9:
                        break
                # pivot: column enter replaces slot i
                i = leave[enter]
                for s in range(s_max):
                    col[s] = T[q, s, enter]
                p = col[i]
                t = lam[q, i] / p
                for s in range(s_max):
                    lam[q, s] -= t * col[s]
                lam[q, i] = t
                for c in range(k):
                    prow[c] = T[q, i, c] / p
                for s in range(s_max):
                    for c in range(k):
                        T[q, s, c] -= col[s] * prow[c]
                for c in range(k):
                    T[q, i, c] = prow[c]
                old = slot_col[q, i]
                slot_col[q, i] = enter
                eligible[q, enter] = False
                eligible[q, old] = True
                made += 1
            if phase == 0:
                most_lp = max(most_lp, made)
            else:
                most_ex = max(most_ex, made)
    return most_lp + most_ex


def _exact_weights(tab: _Tableau, zt: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The barycentric weights of y* on the final support, solved afresh (no drift from the
    pivots): (n, k) weights and (n,) bool, True where they are a valid convex combination giving
    y* back (an exchange is kept only then)."""
    n, k = zt.shape[:2]
    in_slot, slot_col = tab.in_slot, tab.slot_col
    cols = np.maximum(slot_col, 0)
    Z_S = np.take_along_axis(zt, cols[:, :, None], axis=1) * in_slot[:, :, None]
    lam = _solve(_lifted_gram(Z_S, in_slot), in_slot[:, :, None].astype(float))[:, :, 0]
    miss = np.sqrt((np.einsum("qs,qsd->qd", lam, Z_S) ** 2).sum(1))
    convex = (np.where(in_slot, lam, 0.0) >= -1e-9).all(1) & (np.abs(lam.sum(1) - 1) <= 1e-9)
    good = (miss <= 1e-9) & convex
    lam = np.where(in_slot, np.maximum(lam, 0.0), 0.0)
    lam /= lam.sum(1, keepdims=True)
    new_w = np.zeros((n, k))
    new_w[np.nonzero(in_slot)[0], slot_col[in_slot]] = lam[in_slot]
    return new_w, good


def _lifted_gram(Z_S: np.ndarray, in_slot: np.ndarray) -> np.ndarray:
    """(n, s, s) lifted Gram matrix Z_S Z_S^T + 1 1^T of the slots; empty slots get the identity
    and a 1e-12 ridge keeps a degenerate support solvable."""
    s_max = in_slot.shape[1]
    H = Z_S @ Z_S.transpose(0, 2, 1) + in_slot[:, :, None] * in_slot[:, None, :]
    H += np.eye(s_max) * ((~in_slot)[:, :, None] + 1e-12)
    return H


def _solve(H: np.ndarray, rhs: np.ndarray) -> np.ndarray:
    """Batched ``H x = rhs``; a problem whose H is numerically singular (exact duplicate
    neighbours) gets the least-squares answer instead of failing the batch. The checks after
    the exchanges reject any such answer that is not a valid convex combination."""
    try:
        return np.linalg.solve(H, rhs)
    except np.linalg.LinAlgError:
        out = np.empty(rhs.shape)
        for q in range(H.shape[0]):
            try:
                out[q] = np.linalg.solve(H[q], rhs[q])
            except np.linalg.LinAlgError:
                out[q] = np.linalg.lstsq(H[q], rhs[q], rcond=None)[0]
        return out
