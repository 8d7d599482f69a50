"""Exact k nearest corpus rows of a batch of queries with no index: one pass over the beliefs.

What ``decompose(beliefs, queries)`` uses when it is given no index. A prebuilt flat index
answers a batch by its cell search (cells.py), whose k-means cells cost far more to build than
one control step's search; built for a single call they dominate it (docs/notes/benchmarks-rounds.md,
"`decompose` without an index").
This search builds nothing that outlives the call, in four steps for the Q queries of a batch:

1. the batch's centre c (the mean query) and every row's distance rho = ||b - c|| (one pass);
2. a pool, the P = max(4k, 128) rows nearest to c: each query's k-th distance T within the pool
   bounds its true k-th distance from above;
3. a query whose k nearest pool rows lie within (pool radius - ||y - c||) is answered by the
   pool (triangle inequality: no other row can be as near; pooled.within_pool);
4. every other query scans the rows with |rho - ||y - c||| <= T (triangle inequality again),
   sorted by rho so that they are one slice found by binary search, filtered by a float32
   distance with its rounding bound.

Each row's rank is its float64 squared distance from the differences, summed in order, with
ties by the lower row: the same numbers and order as the cell search and ``exact_among``, so the
answer is exactly a flat index's batch answer. The work is O(N d) for the pass and a sort of the
rows within reach of the batch; a batch spread over the whole corpus costs a brute-force search.

Shapes: beliefs (N, d), queries (Q, d); results (Q, k) Euclidean distances float64 ascending and
rows int64, padded with inf / -1 beyond the rows available.
"""

from __future__ import annotations

import numba
import numpy as np

from aoc_cli.errors import AocError
from aoc_cli.index.search.faiss_kinds import as_queries
from aoc_cli.index.search.pooled import exact_among, within_pool
from aoc_cli.index.search.scan_kernels import replace_top, sort_heaps, sq32, up32

#: Rows in the pool searched at the batch's centre, as a multiple of k (and at least POOL_MIN).
POOL_FACTOR = 4
POOL_MIN = 128
#: Relative slack of the triangle-inequality tests (far above the rounding of rho and T).
SLACK = 1e-9


def nearest_rows(beliefs: np.ndarray, queries: np.ndarray, k: int,
                 selection=None) -> tuple[np.ndarray, np.ndarray]:
    """The k nearest corpus rows of every query, exactly, with no index (module docstring).

    beliefs: (N, d) corpus beliefs (used as float32, as an index stores them; a float32 array,
    e.g. a memory map, is read in place); queries: (Q, d) or (d,); selection: None, an (N,) bool
    row mask or an array of row ids. Returns (distances (Q, k) float64, rows (Q, k) int64).
    """
    B = np.asarray(beliefs)
    if B.ndim != 2 or B.shape[0] == 0:
        raise AocError(f"the corpus beliefs must be a non-empty (N, d) array; got shape {B.shape}")
    if k < 1:
        raise AocError(f"k must be at least 1 (got {k}); ask for one or more neighbours")
    Y32 = as_queries(queries, B.shape[1])
    rows = _selected(selection, B.shape[0])
    V = B if rows is None else B[rows]
    if V.dtype != np.float32 or not V.flags.c_contiguous:
        V = np.ascontiguousarray(V, dtype=np.float32)
    kk = min(int(k), V.shape[0])
    dist = np.full((Y32.shape[0], int(k)), np.inf)
    pos = np.full((Y32.shape[0], int(k)), -1, dtype=np.int64)
    if Y32.shape[0]:
        dist[:, :kk], pos[:, :kk] = _search(V, Y32, kk)
    if rows is not None:
        pos = np.where(pos >= 0, rows[np.maximum(pos, 0)], -1)
    return np.sqrt(np.maximum(dist, 0.0)), pos


def _selected(selection, n_rows: int) -> np.ndarray | None:
    """The selected rows (ascending int64), or None for all."""
    if selection is None:
        return None
    sel = np.asarray(selection)
    if sel.dtype == bool:
        if sel.shape != (n_rows,):
            raise AocError(f"row mask has shape {sel.shape}, the corpus has {n_rows} rows; pass one flag per row")
        rows = np.flatnonzero(sel)
    else:
        if sel.size and not np.issubdtype(sel.dtype, np.integer):
            raise AocError("a selection is a boolean row mask or an array of integer row ids")
        rows = np.unique(sel.astype(np.int64).ravel())
        if rows.size and (rows[0] < 0 or rows[-1] >= n_rows):
            raise AocError(f"selected row ids must lie in [0, {n_rows}); check the selection")
    if rows.size == 0:
        raise AocError("the selection leaves no corpus rows; select at least one row")
    return rows


def _search(V: np.ndarray, Y32: np.ndarray, k: int) -> tuple[np.ndarray, np.ndarray]:
    """Squared distances (Q, k) and positions into V (N, d) float32 of Y32's k nearest rows."""
    n = V.shape[0]
    pool_size = max(POOL_FACTOR * k, POOL_MIN)
    if n <= 2 * pool_size:
        return exact_among(Y32, V, k)
    Y = Y32.astype(np.float64)
    centre = Y.mean(axis=0)
    rho2 = np.empty(n)
    _centre_sq(V, centre, rho2)
    pool, pool_d2 = _pool(rho2, pool_size)
    d2, p = exact_among(Y32, V[pool], k)
    pos = pool[p]
    rest = np.flatnonzero(~within_pool(d2[:, -1], Y, centre, pool_d2))
    if rest.size == 0:
        return d2, pos
    Yr = Y[rest]
    spread = np.sqrt(((Yr - centre) ** 2).sum(axis=1))
    T = np.sqrt(d2[rest, -1])
    reach = float((spread + T).max()) * (1.0 + SLACK) + 1e-30
    near = np.flatnonzero(rho2 <= reach * reach)
    near = near[np.argsort(rho2[near], kind="stable")]
    # searched along the batch's main direction, each query's bound tightened by the one
    # before it (three power iterations from the farthest query; the order decides no answer)
    centred = Yr - Yr.mean(axis=0)
    v = centred[np.argmax(np.einsum("qd,qd->q", centred, centred))]
    for _ in range(3):
        v = centred.T @ (centred @ v)
    seq = np.argsort(centred @ v, kind="stable")
    out_d2 = np.empty((rest.size, k))
    out_pos = np.empty((rest.size, k), dtype=np.int64)
    _slice_knn(V, near, np.sqrt(rho2[near]), np.ascontiguousarray(Y32[rest]), Yr, seq, spread, T,
               out_pos, out_d2)
    d2[rest], pos[rest] = out_d2, out_pos
    return d2, pos


def _pool(rho2: np.ndarray, size: int) -> tuple[np.ndarray, float]:
    """About ``size`` (at least size / 2, at least 2k) rows nearest the centre, ascending, and
    a squared radius r2 with every pool row's rho2 <= r2 < every other row's: a quantile of a
    sample of rho2 (no partition of all N), else an exact partition."""
    n = rho2.shape[0]
    rng = np.random.default_rng(n)
    sample = rho2[rng.integers(0, n, 4096)]
    r2 = float(np.partition(sample, int(4096 * size / n))[int(4096 * size / n)])
    pool = np.flatnonzero(rho2 <= r2)
    if size // 2 <= pool.size <= 4 * size:
        return pool, r2
    part = np.argpartition(rho2, size - 1)
    r2 = float(rho2[part[size - 1]])
    return np.flatnonzero(rho2 <= r2), r2


@numba.njit(cache=True, nogil=True, fastmath={"reassoc", "contract"})
def _centre_sq(V, c, out):  # pragma: no cover - compiled
    """out[m] = ||V[m] - c||^2 in float64 (V (N, d) float32, c (d,) float64; summed in any
    order: within d 2^-52 of the exact value, relatively, far below the tests' SLACK)."""
    n, d = V.shape
    for m in range(n):
        e = 0.0
        for t in range(d):
            x = np.float64(V[m, t]) - c[t]
            e += x * x
        out[m] = e


@numba.njit(cache=True, nogil=True)
def _slice_knn(V, near, rho, Y32, Y, seq, spread, T, out_pos, out_d2):  # pragma: no cover - compiled
    """Each query i's k nearest rows of V, whose k-th distance is at most T[i]: the rows near
    (ascending by rho, their distance to the centre) with |rho - spread[i]| <= T[i], a float32
    distance (within (d + 2) 2^-24 of the exact value, relatively) as a filter, the float64
    distance of the differences summed in order to rank, and a heap of the k best by
    (distance, row). Queries go in the order seq; each one's T is also bounded by the one
    before: its k rows lie within T_prev + ||y - y_prev||."""
    Q, d = Y32.shape
    k = out_pos.shape[1]
    hd = np.empty(k)
    hr = np.empty(k, dtype=np.int64)
    prev, reach_prev = -1, np.inf
    for j in range(Q):
        i = seq[j]
        bound = T[i]
        if prev >= 0:
            step = 0.0
            for t in range(d):
                diff = Y[i, t] - Y[prev, t]
                step = step + diff * diff
            bound = min(bound, (reach_prev + np.sqrt(step)) * (1.0 + SLACK) + 1e-30)
        slack = SLACK * (spread[i] + bound) + 1e-30
        a = np.searchsorted(rho, spread[i] - bound - slack)
        b = np.searchsorted(rho, spread[i] + bound + slack, side="right")
        hd[:] = np.inf
        hr[:] = -1
        y32 = Y32[i]
        top = up32(bound * bound * (1.0 + 1e-5) + 1e-30)
        for jj in range(a, b):
            m = near[jj]
            if sq32(V[m], y32) > top:
                continue
            e = 0.0
            for t in range(d):
                diff = np.float64(V[m, t]) - Y[i, t]
                e = e + diff * diff
            if e < hd[0] or (e == hd[0] and m < hr[0]):
                replace_top(hd, hr, e, m)
                if hd[0] < np.inf:
                    top = min(top, up32(hd[0] * (1.0 + 1e-5) + 1e-30))
        prev, reach_prev = i, np.sqrt(hd[0])
        sort_heaps(hd.reshape(1, k), hr.reshape(1, k), out_d2[i:i + 1], out_pos[i:i + 1])
