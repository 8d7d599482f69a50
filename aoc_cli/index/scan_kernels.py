"""Compiled inner loops of the grouped scan (grouped.py): numba, single-threaded, float64 tests.

Both kernels walk the (M, G) float32 matrix D2 of the rows' squared distances to the G group
centroids (minus ||c_g||^2, as the GEMM gives them) once, row by row, so the per-row work is a
few compares instead of several numpy passes over M entries.
"""

from __future__ import annotations

import numba
import numpy as np


@numba.njit(cache=True, nogil=True)
def sample_kth(D2, step, j):  # pragma: no cover - compiled
    """(G,) float64: for each column g, the (j + 1)-th smallest of D2[::step, g] (D2: (M, G)
    float32), kept by an insertion into the j + 1 smallest seen."""
    M, G = D2.shape
    best = np.full((G, j + 1), np.inf, dtype=np.float32)
    for m in range(0, M, step):
        for g in range(G):
            x = D2[m, g]
            if x < best[g, j]:
                b = j
                while b > 0 and best[g, b - 1] > x:
                    best[g, b] = best[g, b - 1]
                    b -= 1
                best[g, b] = x
    return best[:, j].astype(np.float64)


@numba.njit(cache=True, nogil=True)
def rows_under(D2, thresholds):  # pragma: no cover - compiled
    """(p,) int64 ascending rows m with D2[m, g] <= thresholds[g] for some group g.

    D2: (M, G) float32; thresholds: (G,) float64."""
    M, G = D2.shape
    t32 = _up32(thresholds)
    out = np.empty(M, dtype=np.int64)
    n = 0
    for m in range(M):
        hit = False
        for g in range(G):  # branch-free: vectorised
            hit |= D2[m, g] <= t32[g]
        if hit:
            out[n] = m
            n += 1
    return out[:n]


@numba.njit(cache=True, nogil=True, fastmath={"reassoc", "contract"})
def ball_knn(D2, limit, starts, members, hi, lo, Y, u2, rows, Y32, rows32, k, out_rows, out_d2):  # pragma: no cover
    """Exact k nearest rows of every query among the rows its group's centroid bounds keep.

    D2: (M, G) float32 centroid distances (D2 scale: ||b - c_g||^2 - ||c_g||^2, with rounding);
    limit: (G,) a row with D2[m, g] > limit[g] is farther than u_i from every query i of group g;
    starts (G + 1,), members (Q,): the queries of group g are members[starts[g]:starts[g + 1]];
    hi, lo: (Q,) float64, a row with D2[m, g] > hi[i] or < lo[i] (g the group of query i) is
    farther than u_i from query i (its annulus about c_g, rounding included);
    Y: (Q, d) float64 queries and Y32 the same in float32; u2: (Q,) float64 bound on each
    query's k-th squared distance; rows: (M, d) float64 and rows32 (M, d) float32, the rows.

    Fills out_rows (Q, k) int64 and out_d2 (Q, k) float64 (squared distances from the
    differences, ascending; ties by row), and returns the fewest rows any query found within its
    bound (< k: the bound was beaten by rounding, and the answer is incomplete). The float32
    distance (any summation order) only filters; the kept distances are float64, summed in
    order.
    """
    M, G = D2.shape
    Q, d = Y.shape
    heap_d = np.full((Q, k), np.inf)
    heap_r = np.full((Q, k), -1, dtype=np.int64)
    found = np.zeros(Q, dtype=np.int64)
    l32 = _up32(limit)
    hi32 = _up32(hi)
    lo32 = -_up32(-lo)
    # float32 squared distances of float32 data (all terms >= 0) are within (d + 2) 2^-24 of
    # the exact value, relatively: a row whose float32 distance exceeds u2 (1 + 1e-5) is out
    u2f = _up32(u2 * (1.0 + 1e-5))
    for m in range(M):
        hit = False
        for g in range(G):  # branch-free: vectorised; most rows are in no ball
            hit |= D2[m, g] <= l32[g]
        if not hit:
            continue
        for g in range(G):
            x = D2[m, g]
            if x > l32[g]:
                continue
            for s in range(starts[g], starts[g + 1]):
                i = members[s]
                if x > hi32[i] or x < lo32[i]:
                    continue
                e32 = np.float32(0.0)
                for t in range(d):
                    x32 = rows32[m, t] - Y32[i, t]
                    e32 += x32 * x32
                if e32 > u2f[i]:
                    continue
                e = 0.0
                for t in range(d):
                    diff = rows[m, t] - Y[i, t]
                    e = e + diff * diff
                if e > u2[i]:
                    continue
                found[i] += 1
                if e < heap_d[i, 0]:  # a max-heap of the k best (ties: the earlier rows stay)
                    _replace_top(heap_d[i], heap_r[i], e, m)
    _sort_heaps(heap_d, heap_r, out_d2, out_rows)
    return found.min() if Q else k


@numba.njit(cache=True, nogil=True)
def pool_knn(Y, V, k, out_rows, out_d2):  # pragma: no cover - compiled
    """Exact k nearest rows of V for every query of Y (one pass over V per query).

    Y: (Q, d) float32 queries; V: (P, d) float32 rows, P >= k. Fills out_rows (Q, k) int64
    (positions into V) and out_d2 (Q, k) float64 (squared distances from the differences,
    summed in order, ascending; ties by position). The float32 distance only filters: all its
    terms are >= 0, so it is within (d + 2) 2^-24 of the exact value relatively (plus 1e-30
    for underflow), and a row is dropped only if it exceeds the current k-th distance by more.
    """
    Q, d = Y.shape
    P = V.shape[0]
    heap_d = np.full((Q, k), np.inf)
    heap_r = np.full((Q, k), -1, dtype=np.int64)
    e32 = np.empty(P, dtype=np.float32)
    slack = 1.0 + 1e-5
    for i in range(Q):
        hd, hr = heap_d[i], heap_r[i]
        y = Y[i]
        _sq32_rows(V, y, e32)
        top = np.float32(np.inf)
        for m in range(P):
            if e32[m] > top:
                continue
            e = 0.0
            for t in range(d):
                diff = np.float64(V[m, t]) - np.float64(y[t])
                e = e + diff * diff
            if e < hd[0]:  # rows come in order: a tie with the top keeps the earlier row
                _replace_top(hd, hr, e, m)
                if hd[0] < np.inf:
                    bound = hd[0] * slack + 1e-30
                    top = np.float32(bound)
                    if np.float64(top) < bound:
                        top = np.nextafter(top, np.float32(np.inf))
    _sort_heaps(heap_d, heap_r, out_d2, out_rows)


@numba.njit(cache=True, nogil=True)
def _sort_heaps(heap_d, heap_r, out_d2, out_rows):  # pragma: no cover - compiled
    """Each query's k kept (distance, row) pairs ascending by (distance, row): an insertion sort."""
    Q, k = heap_d.shape
    for i in range(Q):
        for a in range(k):
            e, m = heap_d[i, a], heap_r[i, a]
            b = a
            while b > 0 and (out_d2[i, b - 1] > e or (out_d2[i, b - 1] == e and out_rows[i, b - 1] > m)):
                out_d2[i, b] = out_d2[i, b - 1]
                out_rows[i, b] = out_rows[i, b - 1]
                b -= 1
            out_d2[i, b] = e
            out_rows[i, b] = m


@numba.njit(cache=True, nogil=True, fastmath={"reassoc", "contract"})
def _sq32(a, b):  # pragma: no cover - compiled
    """||a - b||^2 of two float32 vectors (summed in any order: vectorised)."""
    e = np.float32(0.0)
    for t in range(a.shape[0]):
        x = a[t] - b[t]
        e += x * x
    return e


@numba.njit(cache=True, nogil=True)
def _up32(x):  # pragma: no cover - compiled
    """x (float64) as float32 rounded up, so a float32 x <= _up32(t) holds whenever x <= t."""
    out = x.astype(np.float32)
    for g in range(x.shape[0]):
        if np.float64(out[g]) < x[g]:
            out[g] = np.nextafter(out[g], np.float32(np.inf))
    return out


@numba.njit(cache=True, nogil=True)
def _replace_top(hd, hr, e, m):  # pragma: no cover - compiled
    """Replace the largest entry of the max-heap (hd, hr), ordered by (distance, row), by
    (e, m) and restore the heap (the entry evicted among equal distances is the latest row)."""
    k = hd.shape[0]
    p = 0
    while True:
        c = 2 * p + 1
        if c >= k:
            break
        if c + 1 < k and (hd[c + 1] > hd[c] or (hd[c + 1] == hd[c] and hr[c + 1] > hr[c])):
            c += 1
        if hd[c] < e or (hd[c] == e and hr[c] < m):
            break
        hd[p] = hd[c]
        hr[p] = hr[c]
        p = c
    hd[p] = e
    hr[p] = m


@numba.njit(cache=True, nogil=True)
def list_dists(c, lists, offsets, vecs):  # pragma: no cover - compiled
    """The float32 squared distances of c to the rows of the given inverted lists.

    c: (d,) float32 point; lists: (p,) int64 list numbers (< 0: none); offsets (nlist + 1,) and
    vecs (N, d) float32: the lists' rows, list after list. Returns (n,) float32 distances (from
    the differences, as FAISS's IVF-Flat scan computes them; within (d + 2) 2^-24 of the exact
    value, relatively) and (n,) int64 the rows' indices into vecs, in list order.
    """
    n = 0
    for l in lists:
        if l >= 0:
            n += offsets[l + 1] - offsets[l]
    dist = np.empty(n, dtype=np.float32)
    idx = np.empty(n, dtype=np.int64)
    n = 0
    for l in lists:
        if l < 0:
            continue
        for m in range(offsets[l], offsets[l + 1]):
            dist[n] = _sq32(vecs[m], c)
            idx[n] = m
            n += 1
    return dist, idx


@numba.njit(cache=True, nogil=True, fastmath={"reassoc", "contract"})
def _sq32_rows(V, y, out):  # pragma: no cover - compiled
    """out[m] = ||V[m] - y||^2 in float32 for the rows of V (summed in any order: vectorised)."""
    P, d = V.shape
    for m in range(P):
        e = np.float32(0.0)
        for t in range(d):
            x = V[m, t] - y[t]
            e += x * x
        out[m] = e
