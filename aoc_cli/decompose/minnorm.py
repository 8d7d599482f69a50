"""Step 2 of the decomposition: the corpus residual, solved exactly for a whole batch at once.

For one query y with neighbour beliefs B (k, d) the corpus residual is the quadratic programme

    r(y) = min_{w in simplex}  || B^T w - y ||,        y* = B^T w,

i.e. the distance from y to the convex hull of its neighbours. Translating the neighbours to
p_c = b_c - y makes it the *minimum-norm point* problem  min_{x in conv(p_1..p_k)} ||x||, which
Wolfe's algorithm (Wolfe 1976, "Finding the nearest point in a polytope") solves exactly in a
finite number of steps: it keeps a "corral" S of affinely independent points and their weights,

    major cycle:  x = sum_{i in S} lam_i p_i;  j = argmin_c <p_c, x>;
                  stop if <x, x> - <p_j, x> <= tol, else S <- S + {j};
    minor cycle:  alpha = argmin { ||sum_S alpha_i p_i|| : sum alpha = 1 } (affine minimiser);
                  if alpha > 0: lam <- alpha, next major cycle;
                  else move lam towards alpha until a weight hits 0 and drop that point.

The stopping test is the optimality condition of the QP (x is the nearest point of the hull iff
<p_c, x> >= <x, x> for every c), so a returned answer is verified, not trusted.

The affine minimiser is never solved from scratch. With the lifted Gram matrix
H_S = P_S P_S^T + 1 1^T (positive definite iff S is affinely independent) the affine minimiser is
alpha = H_S^{-1} 1 / (1^T H_S^{-1} 1), and H_S^{-1} is kept (embedded in a fixed (m, m) slot
array, zero on empty slots) by one rank-one update per cycle:

    add j at empty slot s:   g = H_{S,j}, u = H_S^{-1} g, sigma = H_jj - g.u,
                             H^{-1} <- H^{-1} + (u - e_s)(u - e_s)^T / sigma
    drop slot s:             c = H^{-1} e_s,  H^{-1} <- H^{-1} - c c^T / c_s

so each cycle costs a few small matrix-vector products and no factorisation. Each problem of
the batch runs its own loop in compiled code (numba, float64) and stops as soon as it is
optimal (a lockstep numpy iteration paid ~80 array calls a cycle for the slowest problem).
Problems that do not converge within the budget (degenerate corrals, loss of precision) are
reported as failed and the caller solves them with the reference QP.
"""

from __future__ import annotations

from dataclasses import dataclass

import numba
import numpy as np


@dataclass
class MinNormResult:
    """Per-problem solution of the minimum-norm-point problem.

    weights: (Q, k) float64, the simplex weights w (zero off the support).
    support: (Q, k) bool, the final corral S (affinely independent, at most d + 1 points).
    residual: (Q,) float64, ||B^T w - y|| in the caller's units.
    ok: (Q,) bool, False where the iteration budget ran out or the corral degenerated.
    iterations: the most cycles any problem used.
    """

    weights: np.ndarray
    support: np.ndarray
    residual: np.ndarray
    ok: np.ndarray
    iterations: int


def min_norm_point(
    points: np.ndarray,
    valid: np.ndarray | None = None,
    tol: float = 1e-10,
    max_iter: int | None = None,
) -> MinNormResult:
    """Solve min_{w in simplex} ||sum_c w_c p_c|| for a batch of point sets, exactly.

    points: (Q, k, d) float64, neighbour beliefs minus the query (p_c = b_c - y).
    valid: (Q, k) bool, which points exist (padding when fewer than k neighbours); at least one
        per problem.
    tol: optimality tolerance on the Frank-Wolfe gap <x,x> - min_c <p_c,x>, relative to the
        squared radius of the point set (points are rescaled to radius 1 internally) plus
        1e-10 * ||x||^2, so small residuals are resolved to relative precision.
    """
    points = np.ascontiguousarray(points, dtype=np.float64)
    n_q, k, d = points.shape
    if valid is None:
        valid = np.ones((n_q, k), dtype=bool)
    valid = np.ascontiguousarray(valid, dtype=np.bool_)
    if max_iter is None:
        max_iter = 8 * (min(k, d + 1) + 2) + 20
    weights = np.zeros((n_q, k))
    residual = np.zeros(n_q)
    ok = np.zeros(n_q, dtype=np.bool_)
    iters = np.zeros(n_q, dtype=np.int64)
    if n_q:
        _wolfe_batch(points, valid, float(tol), int(max_iter), weights, residual, ok, iters)
    return MinNormResult(weights, weights > 0, residual, ok, int(iters.max(initial=0)))


@numba.njit(cache=True, nogil=True)
def _wolfe_batch(points, valid, tol, max_iter, out_w, out_res, out_ok, out_it):  # pragma: no cover
    n_q, k, d = points.shape
    m = min(k, d + 1)  # an affinely independent corral has at most d + 1 points
    PT = np.empty((d, k))  # transposed: <p_c, x> for all c vectorises over c
    sq = np.empty(k)
    xP = np.empty(k)
    H = np.zeros((m, m))
    a = np.zeros(m)
    lam = np.zeros(m)
    alpha = np.zeros(m)
    act = np.zeros(m, dtype=np.bool_)
    slot = np.zeros(m, dtype=np.int64)
    Ps = np.zeros((m, d))
    x = np.zeros(d)
    g = np.zeros(m)
    u = np.zeros(m)
    v = np.zeros(m)
    for q in range(n_q):
        # rescale to radius 1
        big = 0.0
        for c in range(k):
            s = 0.0
            for t in range(d):
                s += points[q, c, t] * points[q, c, t]
            sq[c] = s if valid[q, c] else np.inf
            if valid[q, c] and s > big:
                big = s
        scale = np.sqrt(big)
        if not scale > 0:
            scale = 1.0
        s2 = scale * scale
        j0 = 0
        for c in range(k):
            for t in range(d):
                PT[t, c] = points[q, c, t] / scale
            sq[c] = sq[c] / s2
            if sq[c] < sq[j0]:
                j0 = c
        H[:, :] = 0.0
        a[:] = 0.0
        lam[:] = 0.0
        act[:] = False
        H[0, 0] = 1.0 / (sq[j0] + 1.0)
        a[0] = H[0, 0]
        act[0] = True
        slot[0] = j0
        lam[0] = 1.0
        for t in range(d):
            Ps[0, t] = PT[t, j0]
        nact = 1
        failed = False
        done = False
        it = 0
        while it < max_iter:
            it += 1
            asum = 0.0
            for s in range(m):
                asum += a[s]
            minor = False
            for s in range(m):
                alpha[s] = a[s] / asum
                if act[s] and alpha[s] <= 0.0:
                    minor = True
            if not minor:
                for s in range(m):
                    lam[s] = alpha[s]
            # major cycle: optimality test and entering point
            for t in range(d):
                x[t] = 0.0
            for s in range(m):
                if lam[s] != 0.0:
                    for t in range(d):
                        x[t] += lam[s] * Ps[s, t]
            xP[:] = 0.0
            for t in range(d):
                xt = x[t]
                for c in range(k):
                    xP[c] += PT[t, c] * xt
            j = 0
            best = np.inf
            for c in range(k):
                if not valid[q, c]:
                    xP[c] = np.inf
                if xP[c] < best:
                    best = xP[c]
                    j = c
            xx = 0.0
            for t in range(d):
                xx += x[t] * x[t]
            xPj = xP[j]
            gap = xx - xPj  # Frank-Wolfe gap of the best entering point
            # optimal: no gap, or moving towards p_j could lower ||x||^2 by less than 1e-12 of
            # itself (gap^2 / ||p_j - x||^2); adding such a point only degenerates the corral
            step = (sq[j] + 1.0) - 1.0 - 2.0 * xPj + xx  # ||p_j - x||^2
            optimal = (gap - 1e-10 * xx <= tol) or (gap * gap <= 1e-12 * xx * step)
            if nact == m:  # a full corral (d + 1 points, or all k) with alpha > 0: x is optimal
                optimal = True
            if minor:
                # minor cycle: step towards alpha until a weight reaches zero; that point leaves
                s_out = -1
                rbest = np.inf
                for s in range(m):
                    if act[s] and alpha[s] <= 0.0:
                        ratio = lam[s] / max(lam[s] - alpha[s], 1e-300)
                        if ratio < rbest:
                            rbest = ratio
                            s_out = s
                theta = min(rbest, 1.0)
                for s in range(m):
                    lam[s] += theta * (alpha[s] - lam[s])
                c_out = H[s_out, s_out]
                if c_out <= 0.0:
                    failed = True
                    break
                # drop slot s: H^{-1} <- H^{-1} - c c^T / c_s
                for s in range(m):
                    v[s] = H[s, s_out]
                for s in range(m):
                    f = v[s] / c_out
                    for t in range(m):
                        H[s, t] -= f * v[t]
                vs = 0.0
                for t in range(m):
                    vs += v[t]
                for s in range(m):
                    a[s] -= v[s] * vs / c_out
                act[s_out] = False
                lam[s_out] = 0.0
                for s in range(m):
                    H[s_out, s] = 0.0
                    H[s, s_out] = 0.0
                a[s_out] = 0.0
                nact -= 1
                continue
            if optimal:
                done = True
                break
            # j enters at a free slot s: H^{-1} <- H^{-1} + (u - e_s)(u - e_s)^T / sigma
            s_in = 0
            while act[s_in]:
                s_in += 1
            for s in range(m):
                if act[s]:
                    e = 1.0
                    for t in range(d):
                        e += Ps[s, t] * PT[t, j]
                    g[s] = e
                else:
                    g[s] = 0.0
            sigma = sq[j] + 1.0
            for s in range(m):
                e = 0.0
                for t in range(m):
                    e += H[s, t] * g[t]
                u[s] = e
                sigma -= g[s] * e
            u[s_in] -= 1.0
            if sigma <= 1e-12:
                # j lies (numerically) in the corral's affine hull, where <p, x> = <x, x>: a gap
                # of the size of its distance from that hull is rounding, and x is optimal
                failed = not (gap <= 10.0 * np.sqrt(max(sigma, 0.0)) + 1e-12)
                done = True
                break
            us = 0.0
            for t in range(m):
                us += u[t]
            for s in range(m):
                f = u[s] / sigma
                for t in range(m):
                    H[s, t] += f * u[t]
                a[s] += f * us
            act[s_in] = True
            slot[s_in] = j
            for t in range(d):
                Ps[s_in, t] = PT[t, j]
            nact += 1
        out_it[q] = it
        out_ok[q] = done and not failed
        # the weights on the corral, normalised, and the residual they give
        wsum = 0.0
        for s in range(m):
            if act[s]:
                wsum += lam[s]
        for t in range(d):
            x[t] = 0.0
        for s in range(m):
            if act[s]:
                w = lam[s] / wsum
                out_w[q, slot[s]] += w
                for t in range(d):
                    x[t] += w * Ps[s, t]
        xx = 0.0
        for t in range(d):
            xx += x[t] * x[t]
        out_res[q] = np.sqrt(xx) * scale
