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
helps or the budget is spent.
"""

from __future__ import annotations

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
    n_q, k, d = points.shape
    support = weights > 0
    weights = np.where(support, weights, 0.0)
    scale2 = np.maximum(np.max(np.where(valid, (points**2).sum(-1), 0.0), axis=1), 1e-300)
    z = points - offset[:, None, :]  # neighbours relative to y*
    xx = (offset**2).sum(-1)
    on_face = np.abs(np.einsum("qkd,qd->qk", points, offset) - xx[:, None]) <= face_tol * scale2[:, None]
    candidate = valid & on_face & ~support
    s = support.sum(1)
    todo = np.flatnonzero((s >= 2) & candidate.any(1))
    if todo.size == 0:
        return weights, support, 0

    # tableau of the problems with something to exchange, slots padded to s_max
    # rescale about y* (barycentric coordinates are unchanged) so every system is well scaled
    zt = z[todo] / np.sqrt(scale2[todo])[:, None, None]
    sup, cand = support[todo], candidate[todo]
    n = todo.size
    s_max = int(s[todo].max())
    order = np.argsort(~sup, axis=1, kind="stable")[:, :s_max]  # support columns first
    in_slot = np.take_along_axis(sup, order, axis=1)  # (n, s_max) real slot?
    Z_S = np.take_along_axis(zt, order[:, :, None], axis=1) * in_slot[:, :, None]
    H = Z_S @ Z_S.transpose(0, 2, 1) + in_slot[:, :, None] * in_slot[:, None, :]
    H += np.eye(s_max) * ((~in_slot)[:, :, None] + 1e-12)  # ridge: a degenerate support stays solvable
    rhs = np.einsum("qsd,qkd->qsk", Z_S, zt) + in_slot[:, :, None]
    sol = _solve(H, np.concatenate([rhs, in_slot[:, :, None].astype(float)], axis=2))
    T, lam = sol[:, :, :k], sol[:, :, k]
    fit = np.einsum("qsk,qsd->qkd", T, Z_S) - zt
    in_aff = (fit**2).sum(-1) + (T.sum(1) - 1.0) ** 2 <= 1e-14
    eligible = cand & in_aff & valid[todo]
    slot_col = np.where(in_slot, order, -1)
    r = np.arange(n)
    sq = (zt**2).sum(-1)
    pivots = 0

    def pivot(mask: np.ndarray, enter: np.ndarray, leave: np.ndarray) -> None:
        rows = r[mask]
        c, i = enter[rows], leave[rows]
        col = T[rows, :, c]  # (m, s_max)
        piv = col[np.arange(rows.size), i]
        t = lam[rows, i] / piv
        lam[rows] -= t[:, None] * col
        lam[rows, i] = t
        prow = T[rows, i, :] / piv[:, None]
        T[rows] -= col[:, :, None] * prow[:, None, :]
        T[rows, i, :] = prow
        old = slot_col[rows, i]
        slot_col[rows, i] = c
        eligible[rows, c] = False
        eligible[rows, old] = True

    def ratio_test() -> tuple[np.ndarray, np.ndarray]:
        """Leaving slot for every entering column, and its pivot element."""
        pos = (T > 1e-12) & in_slot[:, :, None]
        ratio = np.where(pos, lam[:, :, None] / np.where(pos, T, 1.0), np.inf)
        leave = np.argmin(ratio, axis=1)  # (n, k)
        return leave, np.take_along_axis(T, leave[:, None, :], axis=1)[:, 0, :]

    if lp_start:
        for _ in range(4 * (d + 1) + 16):
            cost_S = np.where(in_slot, sq[r[:, None], np.maximum(slot_col, 0)], 0.0)
            reduced = sq - np.einsum("qs,qsk->qk", cost_S, T)
            leave, piv = ratio_test()
            reduced = np.where(eligible & (piv > 1e-9), reduced, 0.0)
            enter = np.argmin(reduced, axis=1)
            go = reduced[r, enter] < -1e-12
            if not go.any():
                break
            pivot(go, enter, leave[r, enter])
            pivots += 1

    for _ in range(budget):
        leave, piv = ratio_test()
        factor = np.where(eligible & (piv > 1e-9), piv, np.inf)
        enter = np.argmin(factor, axis=1)
        go = factor[r, enter] < 1.0 - 1e-9
        if not go.any():
            break
        pivot(go, enter, leave[r, enter])
        pivots += 1

    # exact barycentric weights on the final support (no drift from the pivots)
    cols = np.maximum(slot_col, 0)
    Z_S = np.take_along_axis(zt, cols[:, :, None], axis=1) * in_slot[:, :, None]
    H = Z_S @ Z_S.transpose(0, 2, 1) + in_slot[:, :, None] * in_slot[:, None, :]
    H += np.eye(s_max) * ((~in_slot)[:, :, None] + 1e-12)
    lam = _solve(H, in_slot[:, :, None].astype(float))[:, :, 0]
    # keep an exchange only if its weights are a valid convex combination giving y* back
    miss = np.sqrt((np.einsum("qs,qsd->qd", lam, Z_S) ** 2).sum(1))
    good = (miss <= 1e-9) & (np.where(in_slot, lam, 0.0) >= -1e-9).all(1) & (np.abs(lam.sum(1) - 1) <= 1e-9)
    lam = np.where(in_slot, np.maximum(lam, 0.0), 0.0)
    lam /= lam.sum(1, keepdims=True)
    new_w = np.zeros((n, k))
    new_w[np.nonzero(in_slot)[0], slot_col[in_slot]] = lam[in_slot]
    weights = weights.copy()
    support = support.copy()
    weights[todo[good]] = new_w[good]
    support[todo[good]] = new_w[good] > 0
    return weights, support, pivots


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
