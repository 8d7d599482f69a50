"""Batched search of an HNSW index (or an IVF other than IVF-Flat L2): one search at the
batch's centroid serves every query it can certify by the triangle inequality, groups of the
rest are searched at their own centroids, and what is left query by query (see
IndexConfig.pool_factor). A flat or IVF-Flat index uses the exact cell search of
``cells.py`` instead; ``exact_among`` also serves small selections of any index.

Shapes: Y (Q, d) float32 queries; results (Q, k) squared distances float64 and positions int64.
"""

from __future__ import annotations

import math

import numpy as np

from aoc_cli.index.search.scan_kernels import pool_knn
from aoc_cli.threads import faiss_threads


def pooled_search(ix, Y: np.ndarray, k: int, sel, available: int, depth: int = 0):
    """One search at the centroid serves every query it can certify (triangle inequality).

    The pool starts at k' = max(pool_factor k, pool_min) rows and doubles (at most twice)
    while 30-95% of the queries are certified; queries still uncertified are searched
    directly. (In d = 20 the k'-th distance grows like k'^(1/20): when the batch spreads
    over a distance comparable to the k-th neighbour distance no affordable pool certifies
    it, so doubling further does not pay.)
    """
    cfg = ix.config
    kp = int(min(available, max(math.ceil(cfg.pool_factor * k), cfg.pool_min, k)))
    c = Y.mean(axis=0, keepdims=True)
    for attempt in range(3):
        with faiss_threads(1):  # one query: threads only add synchronisation
            Dc, Ic = ix.index.search(c, kp, params=ix._params(sel, kp))
        pool = Ic[0][Ic[0] >= 0]
        if pool.size < k:
            return ix._direct(Y, k, sel)
        d2, p = exact_among(Y, ix.vectors(pool), k)
        pos = pool[p]
        if pool.size >= available:
            return d2, pos  # the pool is every available row
        if pool.size < kp:  # an IVF ran out of probed rows: the pool bounds nothing
            return ix._direct(Y, k, sel)
        certified = within_pool(d2[:, -1], Y, c[0], float(Dc[0, pool.size - 1]))
        if certified.all() or kp >= available:
            return d2, pos
        if attempt < 2 and 0.3 <= certified.mean() < 0.95:
            kp = int(min(available, 2 * kp))
            continue
        break
    rest = np.flatnonzero(~certified)
    d2[rest], pos[rest] = _split(ix, Y[rest], k, sel, available, depth)
    return d2, pos

def _split(ix, Y: np.ndarray, k: int, sel, available: int, depth: int):
    """Uncertified queries: cut them into groups along their main direction, search every
    group's centroid in one FAISS call and certify each group against its own pool.

    Real control steps spread their candidates along a curve in belief space (the action
    moves the belief): one centroid cannot certify the whole batch, but groups with an
    eighth of its spread can, for the price of one more index scan. Queries still
    uncertified are grouped again (three rounds at most), then searched directly.
    IVF: one round of 16 groups with six times the pool (an IVF search costs its probed
    lists whatever k; faster on pendulum control steps than three rounds, the same recall:
    docs/notes/benchmarks-rounds.md, "Figures once in docstrings").
    """
    n = Y.shape[0]
    ivf = ix.kind == "ivf"
    if depth > (0 if ivf else 2) or n < 6:
        return ix._direct(Y, k, sel)
    centred = Y.astype(np.float64) - Y.mean(axis=0)
    direction = np.linalg.svd(centred, full_matrices=False)[2][0]
    n_groups = min(16 if ivf else 8, n // 3)
    groups = np.array_split(np.argsort(centred @ direction, kind="stable"), n_groups)
    C = np.stack([Y[g].mean(axis=0) for g in groups]).astype(np.float32)
    cfg = ix.config
    base = max(math.ceil(cfg.pool_factor * k), cfg.pool_min, k)
    kp = int(min(available, (6 if ivf else 2) * base))
    with faiss_threads(1):
        Dc, Ic = ix.index.search(C, kp, params=ix._params(sel, kp))
    d2 = np.empty((n, k))
    pos = np.empty((n, k), dtype=np.int64)
    todo = np.zeros(n, dtype=bool)
    for j, g in enumerate(groups):
        pool = Ic[j][Ic[j] >= 0]
        r2 = float(Dc[j, pool.size - 1]) if pool.size else -1.0
        V = ix.vectors(pool) if pool.size >= kp else None
        if pool.size < kp:  # too few rows (selection, IVF): the pool bounds nothing
            todo[g] = True
            continue
        gd2, gp = exact_among(Y[g], V, k)
        d2[g], pos[g] = gd2, pool[gp]
        todo[g] = ~within_pool(gd2[:, -1], Y[g], C[j], r2)
    rest = np.flatnonzero(todo)
    if rest.size:
        d2[rest], pos[rest] = _split(ix, Y[rest], k, sel, available, depth + 1)
    return d2, pos


def exact_among(Y: np.ndarray, V: np.ndarray, k: int) -> tuple[np.ndarray, np.ndarray]:
    """Squared distances (float64, ascending) and positions (into V) of the k nearest rows of V.

    Y: (Q, d) queries, V: (P, d) rows (both used as float32); results (Q, min(k, P)). Exact:
    one compiled pass over V per query (``scan_kernels.pool_knn``), a float32 distance as a
    filter with its rounding bound, the float64 distance of the differences for the rows that
    pass, and a heap of the k nearest ordered by (distance, position), so ties keep the lower
    position.
    """
    Y32 = np.ascontiguousarray(Y, dtype=np.float32)
    V32 = np.ascontiguousarray(V, dtype=np.float32)
    k = min(int(k), V32.shape[0])
    d2 = np.empty((Y32.shape[0], k))
    pos = np.empty((Y32.shape[0], k), dtype=np.int64)
    if k > 0:
        pool_knn(Y32, V32, k, pos, d2)
    return d2, pos


def within_pool(kth_d2: np.ndarray, Y: np.ndarray, centre: np.ndarray,
                pool_d2: float) -> np.ndarray:
    """The pool certificate: (Q,) bool, True where a query's k nearest rows are certainly
    among the pool, the rows within squared distance ``pool_d2`` of ``centre`` (d,).

    kth_d2: (Q,) each query's k-th squared distance within the pool; Y: (Q, d) the queries.
    By the triangle inequality a row nearer to query y than its k-th pool row (distance
    kth) is within kth + ||y - centre|| of the centre; when that is inside the pool's radius
    (less a relative 1e-5 for rounding), no row outside the pool can be among y's k nearest.
    """
    radius = math.sqrt(max(pool_d2, 0.0))
    spread = np.sqrt(((Y.astype(np.float64) - centre.astype(np.float64)) ** 2).sum(axis=1))
    kth = np.sqrt(np.maximum(kth_d2, 0.0))
    return kth <= (radius - spread) - 1e-5 * radius
