"""Step 2 of the decomposition: the corpus residual, solved exactly for a whole batch at once.

For one query y with neighbour beliefs B (k, d) the corpus residual is the quadratic programme

    r(y) = min_{w in simplex}  || B^T w - y ||,        y* = B^T w,

i.e. the distance from y to the convex hull of its neighbours. Translating the neighbours to
p_c = b_c - y makes it the *minimum-norm point* problem  min_{x in conv(p_1..p_k)} ||x||, which
Wolfe's algorithm (Wolfe 1976, "Finding the nearest point in a polytope") solves exactly in a
finite number of steps: it keeps a "corral" S of affinely independent points and their weights,

    major cycle:  x = sum_{i in S} lam_i p_i;  j = argmin_c <p_c, x>;
                  stop if x is certified optimal (below), else S <- S + {j};
    minor cycle:  alpha = argmin { ||sum_S alpha_i p_i|| : sum alpha = 1 } (affine minimiser);
                  if alpha > 0: lam <- alpha, next major cycle;
                  else move lam towards alpha until a weight hits 0 and drop that point.

The stopping test is the optimality condition of the QP (x is the nearest point of the hull iff
<p_c, x> >= <x, x> for every c), so a returned answer is verified, not trusted. With the
Frank-Wolfe gap  gap = <x, x> - min_c <p_c, x>  every point of the hull has <p, x> >= <x, x> - gap,
hence  r* >= ||x|| - gap / ||x||  (and r* >= 0): the loop stops when (points rescaled to radius 1)

    ||x|| <= ABS_TOL   or   gap <= tol ||x||^2 + GAP_TOL,

i.e. when ||x|| - r* <= min(||x||, tol ||x|| + GAP_TOL / ||x||): relative to ||x|| itself, not
to the radius. An absolute test gap <= tol bounds ||x||^2 - r*^2, which near a zero residual
allows ||x|| several times r*. GAP_TOL = 1e-15 is the floor of the computed gap (x carries
rounding of ~1e-16 at radius 1, and so does <x, x> - <p_j, x>: on the recorded upright problems
1e-16 certifies half of them, 1e-15 all), so a residual near 3e-8 of the radius is certified to
~3e-8 at worst (ABS_TOL): below the precision of float32 beliefs (~6e-8 of their own magnitude,
which exceeds the radius).

The affine minimiser is never solved from scratch. With the lifted points q_c = (p_c, 1) and the
lifted Gram matrix H_S = P_S P_S^T + 1 1^T (positive definite iff S is affinely independent),
alpha = H_S^{-1} 1 / (1^T H_S^{-1} 1). The loop keeps a QR factorisation of the lifted corral,
[q_i]_{i in S} = U R (U (d + 1, |S|) orthonormal columns, R upper triangular, H_S = R^T R), and
gets alpha by two triangular solves (R^T z = 1, R a = z):

    add j:    Gram-Schmidt of q_j against U (r = U^T q_j, e = q_j - U r, rho = ||e||; a second
              pass when the first cancelled more than half of ||q_j||^2):
              U <- [U, e / rho], R <- [[R, r], [0, rho]]
    drop i:   delete column i of R and restore its triangle by Givens rotations of rows
              (t, t + 1), t >= i, applied to U's columns alike

so each cycle costs a few small matrix-vector products and no factorisation. rho is the
distance of q_j from the corral's span computed from the difference vector itself, exact to
rounding even for nearly duplicate points; the previous rank-one update of H_S^{-1} got it
as H_jj - g^T H_S^{-1} g, which loses all precision when S is nearly affinely dependent
(beliefs of a trained network on a low-dimensional surface: H_S's condition number is the
square of the lifted points'; docs/notes/benchmarks-rounds.md, "The residual QP per belief"). A point with
rho <= RHO_MIN lies in the corral's affine hull, where its gap is rounding: x is then accepted
when that gap passes the test above with 10 rho ||x|| added. Each problem of
the batch runs its own loop in compiled code (numba, float64) and stops as soon as it is
optimal (a lockstep numpy iteration paid ~80 array calls a cycle for the slowest problem).
Problems that are not certified within the budget (cycling, a degenerate corral) are
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
    tol: relative optimality tolerance: a problem stops when the Frank-Wolfe gap
        <x,x> - min_c <p_c,x> is at most tol ||x||^2 + GAP_TOL, or ||x|| <= ABS_TOL (points
        rescaled to radius 1 internally), so ||x|| - r* <= tol ||x|| + GAP_TOL / ||x||
        (module docstring).
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


#: The certificate's floors, on the unit-radius scale: a problem is solved when ||x|| <= ABS_TOL
#: or gap <= tol ||x||^2 + GAP_TOL, so ||x|| - r* <= min(||x||, tol ||x|| + GAP_TOL / ||x||).
ABS_TOL = 3e-8
GAP_TOL = 1e-15
#: A point whose lifted distance from the span of the lifted corral is below this (unit
#: radius) lies in the corral's affine hull up to rounding: it is not added.
RHO_MIN = 1e-12


@numba.njit(cache=True, nogil=True)
def _wolfe_batch(points, valid, tol, max_iter, out_w, out_res, out_ok, out_it):  # pragma: no cover
    n_q, k, d = points.shape
    D = d + 1  # lifted points q_c = (p_c, 1)
    m = min(k, D)  # an affinely independent corral has at most d + 1 points
    PT = np.empty((d, k))  # transposed: <p_c, x> for all c vectorises over c
    sq = np.empty(k)
    xP = np.empty(k)
    Ut = np.zeros((m, D))  # rows: an orthonormal basis of the lifted corral's span (U^T)
    R = np.zeros((m, m))  # the lifted corral (as columns) = U R, R upper triangular
    lam = np.zeros(m)
    alpha = np.zeros(m)
    a = np.zeros(m)
    z = np.zeros(m)
    r = np.zeros(m)
    idx = np.zeros(m, dtype=np.int64)
    x = np.zeros(d)
    e = np.zeros(D)
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
        # the corral {j0}: q_j0 = Ut[0] R[0, 0]
        Ut[:, :] = 0.0
        R[:, :] = 0.0
        lam[:] = 0.0
        nrm = 0.0
        for t in range(d):
            nrm += PT[t, j0] * PT[t, j0]
        nrm = np.sqrt(nrm + 1.0)
        for t in range(d):
            Ut[0, t] = PT[t, j0] / nrm
        Ut[0, d] = 1.0 / nrm
        R[0, 0] = nrm
        idx[0] = j0
        lam[0] = 1.0
        n = 1
        failed = False
        done = False
        it = 0
        while it < max_iter:
            it += 1
            # the corral's affine minimiser: alpha = H^{-1} 1 / (1^T H^{-1} 1), H = R^T R
            for i in range(n):  # R^T z = 1
                s = 1.0
                for t in range(i):
                    s -= R[t, i] * z[t]
                z[i] = s / R[i, i]
            for i in range(n - 1, -1, -1):  # R a = z
                s = z[i]
                for t in range(i + 1, n):
                    s -= R[i, t] * a[t]
                a[i] = s / R[i, i]
            asum = 0.0
            for i in range(n):
                asum += a[i]
            minor = False
            for i in range(n):
                alpha[i] = a[i] / asum
                if not alpha[i] > 0.0:
                    minor = True
            if minor:
                # minor cycle: step towards alpha until a weight reaches zero; that point leaves
                i_out = -1
                rbest = np.inf
                for i in range(n):
                    if not alpha[i] > 0.0:
                        ratio = lam[i] / max(lam[i] - alpha[i], 1e-300)
                        if ratio < rbest:
                            rbest = ratio
                            i_out = i
                if i_out < 0:  # alpha not finite: the corral degenerated
                    failed = True
                    break
                theta = min(rbest, 1.0)
                for i in range(n):
                    lam[i] += theta * (alpha[i] - lam[i])
                _drop(Ut, R, idx, lam, n, i_out)
                n -= 1
                continue
            for i in range(n):
                lam[i] = alpha[i]
            # major cycle: optimality test and entering point
            for t in range(d):
                x[t] = 0.0
            for i in range(n):
                li = lam[i]
                c = idx[i]
                for t in range(d):
                    x[t] += li * PT[t, c]
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
            nx = np.sqrt(xx)
            gap = xx - xP[j]  # Frank-Wolfe gap of the best entering point
            # ||x|| - r* <= gap / ||x||: certified to tol relatively, ABS_TOL absolutely; a full
            # corral (d + 1 points, or all k) with alpha > 0 is optimal as it stands
            if nx <= ABS_TOL or gap <= tol * xx + GAP_TOL or n == m:
                done = True
                break
            # j enters: Gram-Schmidt of q_j against U, the new column of R; a second pass when
            # the first cancelled more than half the norm (Daniel-Gragg-Kaufman-Stewart)
            for t in range(d):
                e[t] = PT[t, j]
            e[d] = 1.0
            before = sq[j] + 1.0  # ||q_j||^2
            for i in range(n):
                r[i] = 0.0
            for _rep in range(2):
                for i in range(n):
                    s = 0.0
                    for t in range(D):
                        s += Ut[i, t] * e[t]
                    r[i] += s
                    for t in range(D):
                        e[t] -= s * Ut[i, t]
                rho = 0.0
                for t in range(D):
                    rho += e[t] * e[t]
                if rho > 0.5 * before:
                    break
                before = rho
            rho = np.sqrt(rho)
            if rho <= RHO_MIN:
                # j lies in the corral's affine hull (up to ~2 rho), where <p, x> = <x, x>: a gap
                # of that size is rounding, and x is optimal to within it; anything larger
                # means x lost precision
                failed = not (gap <= tol * xx + GAP_TOL + 10.0 * rho * nx)
                done = True
                break
            for t in range(D):
                Ut[n, t] = e[t] / rho
            for i in range(n):
                R[i, n] = r[i]
            R[n, n] = rho
            idx[n] = j
            lam[n] = 0.0
            n += 1
        out_it[q] = it
        out_ok[q] = done and not failed
        # the weights on the corral, normalised, and the residual they give
        wsum = 0.0
        for i in range(n):
            if lam[i] > 0.0:
                wsum += lam[i]
        for t in range(d):
            x[t] = 0.0
        for i in range(n):
            if lam[i] > 0.0:
                w = lam[i] / wsum
                c = idx[i]
                out_w[q, c] += w
                for t in range(d):
                    x[t] += w * PT[t, c]
        xx = 0.0
        for t in range(d):
            xx += x[t] * x[t]
        out_res[q] = np.sqrt(xx) * scale


@numba.njit(cache=True, nogil=True)
def _drop(Ut, R, idx, lam, n, i):  # pragma: no cover
    """Remove corral member i of n: shift the later columns of R (and idx, lam) left, restore
    R's triangle by Givens rotations of rows (t, t + 1), applied to U's columns (Ut's rows)
    alike."""
    for t in range(i, n - 1):
        idx[t] = idx[t + 1]
        lam[t] = lam[t + 1]
        for s in range(n):
            R[s, t] = R[s, t + 1]
    for t in range(i, n - 1):
        f = R[t, t]
        g = R[t + 1, t]
        h = np.sqrt(f * f + g * g)
        if h > 0.0:
            c = f / h
            s = g / h
            for u in range(t, n - 1):
                r1 = R[t, u]
                r2 = R[t + 1, u]
                R[t, u] = c * r1 + s * r2
                R[t + 1, u] = c * r2 - s * r1
            for v in range(Ut.shape[1]):
                u1 = Ut[t, v]
                u2 = Ut[t + 1, v]
                Ut[t, v] = c * u1 + s * u2
                Ut[t + 1, v] = c * u2 - s * u1
        R[t + 1, t] = 0.0
    for s in range(n):
        R[s, n - 1] = 0.0
        R[n - 1, s] = 0.0
    for v in range(Ut.shape[1]):
        Ut[n - 1, v] = 0.0
    lam[n - 1] = 0.0
    idx[n - 1] = 0
