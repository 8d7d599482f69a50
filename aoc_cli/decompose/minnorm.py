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

Vectorised over the batch: every problem advances one cycle per iteration in lockstep, and the
affine minimiser is never solved from scratch. With the lifted Gram matrix
H_S = P_S P_S^T + 1 1^T (positive definite iff S is affinely independent) the affine minimiser is
alpha = H_S^{-1} 1 / (1^T H_S^{-1} 1), and H_S^{-1} is kept (embedded in a fixed (m, m) slot
array, zero on empty slots) by one rank-one update per cycle:

    add j at empty slot s:   g = H_{S,j}, u = H_S^{-1} g, sigma = H_jj - g.u,
                             H^{-1} <- H^{-1} + (u - e_s)(u - e_s)^T / sigma
    drop slot s:             c = H^{-1} e_s,  H^{-1} <- H^{-1} - c c^T / c_s

so each cycle costs a few batched matrix-vector products and no factorisation. Problems that do
not converge within the budget (degenerate corrals, loss of precision) are reported as failed and
the caller solves them with the reference QP.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass
class MinNormResult:
    """Per-problem solution of the minimum-norm-point problem.

    weights: (Q, k) float64, the simplex weights w (zero off the support).
    support: (Q, k) bool, the final corral S (affinely independent, at most d + 1 points).
    residual: (Q,) float64, ||B^T w - y|| in the caller's units.
    ok: (Q,) bool, False where the iteration budget ran out or the corral degenerated.
    iterations: number of lockstep cycles used.
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
    points = np.asarray(points, dtype=np.float64)
    n_q, k, d = points.shape
    if valid is None:
        valid = np.ones((n_q, k), dtype=bool)
    if max_iter is None:
        max_iter = 8 * (min(k, d + 1) + 2) + 20
    m = min(k, d + 1)  # an affinely independent corral has at most d + 1 points

    sq = np.einsum("qkd,qkd->qk", points, points)
    sq = np.where(valid, sq, np.inf)
    scale = np.sqrt(np.max(np.where(valid, sq, 0.0), axis=1))
    scale = np.where(scale > 0, scale, 1.0)
    P = points / scale[:, None, None]
    sq = sq / (scale**2)[:, None]

    out_w = np.zeros((n_q, k))
    out_res = np.zeros(n_q)
    out_ok = np.zeros(n_q, dtype=bool)

    # state of the live problems; slot arrays are kept contiguous and only as wide as needed
    live = np.arange(n_q)
    r = np.arange(n_q)
    j0 = np.argmin(sq, axis=1)
    mu = 1
    slot = np.zeros((n_q, m), dtype=np.int64)
    slot[:, 0] = j0
    act = np.ones((n_q, mu), dtype=bool)
    nact = np.ones(n_q, dtype=np.int64)
    lam = np.ones((n_q, mu))
    H = (1.0 / (sq[r, j0] + 1.0))[:, None, None].copy()
    a = H[:, :, 0].copy()  # row sums of H^{-1}, kept up to date
    Ps = P[r, j0][:, None, :].copy()
    Pl, sq1 = P, sq + 1.0
    blocked = np.where(valid, 0.0, np.inf) if not valid.all() else None
    done = np.zeros(n_q, dtype=bool)
    failed = np.zeros(n_q, dtype=bool)

    def collect(idx: np.ndarray) -> None:
        q = live[idx]
        w = np.where(act[idx], lam[idx], 0.0)
        w = w / w.sum(axis=1, keepdims=True)
        np.add.at(out_w, (np.repeat(q, mu), slot[idx, :mu].ravel()), w.ravel())
        xf = (w[:, None, :] @ Ps[idx])[:, 0]
        out_res[q] = np.sqrt(np.einsum("qd,qd->q", xf, xf)) * scale[q]
        out_ok[q] = ~failed[idx]

    it = 0
    while it < max_iter:
        it += 1
        if mu < m and nact.max() == mu:  # a corral may grow: widen the slot arrays
            old, mu = mu, min(m, mu + 3)
            act, lam, a, Ps = (_widen(x, old, mu) for x in (act, lam, a, Ps))
            H = _widen(H, old, mu, square=True)
        alpha = a / a.sum(axis=1, keepdims=True)
        neg = act & (alpha <= 0.0)
        minor = neg.any(axis=1)
        any_minor = bool(minor.any())
        lam = np.where(minor[:, None], lam, alpha) if any_minor else alpha

        # major cycle: optimality test and entering point
        x = (lam[:, None, :] @ Ps)[:, 0]
        xP = (Pl @ x[:, :, None])[..., 0]
        if blocked is not None:
            xP += blocked
        j = np.argmin(xP, axis=1)
        xPj, sq1j = xP[r, j], sq1[r, j]
        xx = np.einsum("qd,qd->q", x, x)
        gap = xx - xPj  # Frank-Wolfe gap of the best entering point
        # optimal: no gap, or moving towards p_j could lower ||x||^2 by less than 1e-12 of
        # itself (gap^2 / ||p_j - x||^2); adding such a point only degenerates the corral
        step = sq1j - 1.0 - 2.0 * xPj + xx  # ||p_j - x||^2
        optimal = (gap - 1e-10 * xx <= tol) | (gap * gap <= 1e-12 * xx * step)
        if mu == m:  # a full corral (d + 1 points, or all k) with alpha > 0: x is optimal
            optimal |= nact == m
        done |= optimal & ~minor
        add = ~(minor | done)

        any_add = bool(add.any())
        v = den = None

        # minor cycle: step towards alpha until a weight reaches zero; that point leaves
        if any_minor:
            ratio = np.where(neg, lam / np.maximum(lam - alpha, 1e-300), np.inf)
            s_out = np.argmin(ratio, axis=1)
            theta = np.where(minor, np.minimum(ratio[r, s_out], 1.0), 0.0)
            lam += theta[:, None] * (alpha - lam)
            c = H[r, :, s_out]  # drop slot s: H^{-1} <- H^{-1} - c c^T / c_s
            c_out = c[r, s_out]
            bad = minor & (c_out <= 0.0)
            if bad.any():
                minor &= ~bad
                failed |= bad
                done |= bad
            v = c * minor[:, None]
            den = np.where(minor, -c_out, 1.0)

        # major cycle, continued: j enters at a free slot s: H^{-1} <- H^{-1} + (u-e_s)(u-e_s)^T / sigma
        if any_add:
            s_in = np.argmin(act, axis=1)
            pj = Pl[r, j]
            g = (Ps @ pj[:, :, None])[..., 0] + 1.0
            g *= act
            u = (H @ g[:, :, None])[..., 0]
            sigma = sq1j - np.einsum("qm,qm->q", g, u)
            u[r, s_in] -= 1.0
            bad = add & (sigma <= 1e-12)
            if bad.any():
                # j lies (numerically) in the corral's affine hull, where <p, x> = <x, x>: a gap
                # of the size of its distance from that hull is rounding, and x is optimal
                rounding = bad & (gap <= 10.0 * np.sqrt(np.maximum(sigma, 0.0)) + 1e-12)
                add &= ~bad
                failed |= bad & ~rounding
                done |= bad
            if v is None:
                v = u * add[:, None]
                den = np.where(add, sigma, 1.0)
            else:
                v = np.where(add[:, None], u, v)
                den = np.where(add, sigma, den)

        if v is not None:
            w = v / den[:, None]
            H += v[:, :, None] * w[:, None, :]
            a += v * w.sum(axis=1, keepdims=True)
        if any_minor:
            rm = r[minor]
            so = s_out[rm]
            act[rm, so] = False
            lam[rm, so] = 0.0
            H[rm, so, :] = 0.0
            H[rm, :, so] = 0.0
            a[rm, so] = 0.0
            nact -= minor
        if any_add:
            ad = r[add]
            si = s_in[ad]
            act[ad, si] = True
            slot[ad, si] = j[ad]
            Ps[ad, si] = pj[ad]
            nact += add

        if done.all():
            break
        if 2 * done.sum() >= live.size and live.size > 8:
            fin = np.flatnonzero(done)
            collect(fin)
            keep = ~done
            live = live[keep]
            slot, act, nact, lam, H, a, Ps = slot[keep], act[keep], nact[keep], lam[keep], H[keep], a[keep], Ps[keep]
            Pl, sq1 = Pl[keep], sq1[keep]
            blocked = None if blocked is None else blocked[keep]
            done, failed = done[keep], failed[keep]
            r = np.arange(live.size)
    failed |= ~done
    collect(np.arange(live.size))
    out_support = out_w > 0
    return MinNormResult(out_w, out_support, out_res, out_ok, it)


def _widen(x: np.ndarray, old: int, new: int, square: bool = False) -> np.ndarray:
    """x with its slot axis 1 (and axis 2 too if square) grown from old to new, zero-filled."""
    shape = list(x.shape)
    shape[1] = new
    if square:
        shape[2] = new
    out = np.zeros(shape, dtype=x.dtype)
    if square:
        out[:, :old, :old] = x
    else:
        out[:, :old] = x
    return out
