"""Compiled pieces shared by the exact searches (numba, single-threaded), in one place: the k
nearest rows of a pool (``pool_knn``, pooled.py's ``exact_among``); the heap of the k best
ordered by (distance, position) that it, the cell search (cells.py) and the scan of every row
(exact.py) keep (``replace_top``, ``sort_heaps``); the float32 squared distance they compare
(``sq32``) and a float64 bound rounded up to float32 (``up32``).
"""

from __future__ import annotations

import numba
import numpy as np


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
                replace_top(hd, hr, e, m)
                if hd[0] < np.inf:
                    bound = hd[0] * slack + 1e-30
                    top = np.float32(bound)
                    if np.float64(top) < bound:
                        top = np.nextafter(top, np.float32(np.inf))
    sort_heaps(heap_d, heap_r, out_d2, out_rows)


@numba.njit(cache=True, nogil=True)
def sort_heaps(heap_d, heap_r, out_d2, out_rows):  # pragma: no cover - compiled
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
def sq32(a, b):  # pragma: no cover - compiled
    """||a - b||^2 of two float32 vectors (summed in any order: vectorised)."""
    e = np.float32(0.0)
    for t in range(a.shape[0]):
        x = a[t] - b[t]
        e += x * x
    return e


@numba.njit(cache=True, nogil=True)
def replace_top(hd, hr, e, m):  # pragma: no cover - compiled
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


@numba.njit(cache=True, nogil=True)
def up32(x):  # pragma: no cover - compiled
    """x (float64) as a float32 not below it."""
    out = np.float32(x)
    if np.float64(out) < x:
        out = np.nextafter(out, np.float32(np.inf))
    return out
