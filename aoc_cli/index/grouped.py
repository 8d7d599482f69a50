"""Exact k nearest rows of a batch of queries by one scan of the corpus at group centroids.

The candidates of a control step spread in belief space about as far as their k-th neighbour
distance, and the beliefs (d_b = 20) have a high local dimension, so no single pool around
the batch centroid holds every query's neighbours, and the full (Q, N) distance matrix costs
Q N d_b multiply-adds and Q N memory traffic. Instead:

1. cut the Q queries into G groups of nearby queries (slabs along the batch's main direction)
   and compute the squared distance of each centroid c_g to every row: one (G, d_b + 1) x
   (d_b + 1, N) GEMM against the rows augmented with their squared norms;
2. an upper bound u_i on each query's k-th neighbour distance: its k-th distance among the
   union of the ~`POOL0` rows nearest each centroid;
3. a row b with ||b - c_g|| > R_g = max_i (||y_i - c_g|| + u_i) is farther than u_i from every
   query i of the group (triangle inequality), so the rows within R_g of c_g hold each query's
   exact k nearest rows: rank them (float64), `CHUNKS` consecutive groups at a time against
   the union of their balls (neighbouring balls overlap). Only the few rows within u_i of
   query i can be among its k nearest, so those are sorted instead of selecting among the
   whole ball; the k chosen rows of every query are then re-ranked exactly in one pass.

The centroid distances are float32; the ball test adds a margin bounding their rounding error
(a sum of d_b + 2 products: gamma_{d_b+2} (||c|| + ||b||)^2, doubled), so a row may be kept
needlessly but never dropped wrongly.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

#: Queries per group and the most groups: G = clip(Q // QUERIES_PER_GROUP, 1, MAX_GROUPS).
QUERIES_PER_GROUP = 6
MAX_GROUPS = 16
#: About this many rows nearest each centroid bound its queries' k-th distances.
POOL0 = 128
#: Columns of the strided sample of the centroid distances that sets the stage-1 thresholds.
SAMPLE = 4096
#: Consecutive groups whose balls are searched together (fewer, larger searches).
CHUNKS = 8


@dataclass
class ScanData:
    """What the scan needs of the M indexed rows, computed once per index.

    rows: (M, d) float32 (a view of the index storage); aug_t: (d + 1, M) float32, the rows
    transposed with their squared norms as the last line; norms: (M,) float64 ||v||^2;
    vmax: max ||v||; rows64: (M, d) float64 copy of the rows (the exact ranking gathers from
    it: a contiguous float64 gather is faster than a float32 gather and a cast).
    """

    rows: np.ndarray
    aug_t: np.ndarray
    norms: np.ndarray
    vmax: float
    rows64: np.ndarray

    @classmethod
    def of(cls, rows: np.ndarray) -> "ScanData":
        norms = np.einsum("md,md->m", rows, rows, dtype=np.float64)
        aug_t = np.empty((rows.shape[1] + 1, rows.shape[0]), dtype=np.float32)
        aug_t[:-1] = rows.T
        aug_t[-1] = norms
        return cls(rows, aug_t, norms, float(np.sqrt(norms.max(initial=0.0))),
                   np.ascontiguousarray(rows, dtype=np.float64))


def grouped_search(Y: np.ndarray, scan: ScanData, k: int, mask: np.ndarray | None = None):
    """Exact k nearest rows for every query, or None when the rounding margin was beaten.

    Y: (Q, d) float32 queries; mask: (M,) bool rows allowed (None: all), at least k of them.
    Returns (squared distances (Q, k) float64 ascending, positions (Q, k) int64 into the rows).
    """
    n, d = Y.shape
    M = scan.rows.shape[0]
    Y64 = Y.astype(np.float64)
    groups = _groups(Y64, min(MAX_GROUPS, max(1, n // QUERIES_PER_GROUP)))
    sizes = np.array([g.size for g in groups])
    label = np.repeat(np.arange(len(groups)), sizes)[np.argsort(np.concatenate(groups))]
    starts = np.concatenate(([0], np.cumsum(sizes)[:-1]))
    C = (np.add.reduceat(Y64[np.concatenate(groups)], starts, axis=0) / sizes[:, None]).astype(np.float32)
    C_aug = np.empty((len(groups), d + 1), dtype=np.float32)
    C_aug[:, :-1] = -2.0 * C
    C_aug[:, -1] = 1.0
    D2 = C_aug @ scan.aug_t  # (G, M): ||b||^2 - 2 c.b = ||b - c||^2 - ||c||^2
    if mask is not None:
        D2[:, ~mask] = np.inf
    C64 = C.astype(np.float64)
    cc = (C64 * C64).sum(axis=1)
    eps = 2.0**-24
    gamma = (d + 2) * eps / (1.0 - (d + 2) * eps)
    margin = 2.0 * gamma * (np.sqrt(cc) + scan.vmax) ** 2
    # stage 1: about POOL0 rows nearest each centroid (threshold from a strided sample); each
    # query's k-th distance among their union bounds its k-th neighbour distance from above
    step = max(1, M // SAMPLE)
    sample = D2[:, ::step]
    j = min(sample.shape[1] - 1, POOL0 // step)
    thresholds = np.partition(sample, j, axis=1)[:, j]
    near = np.flatnonzero((D2 <= thresholds[:, None]).any(axis=0)) \
        if np.isfinite(thresholds).all() else np.zeros(0, np.int64)
    if near.size < k:
        near = np.argpartition(D2.min(axis=0), k - 1)[:k]
    yy = (Y64 * Y64).sum(axis=1)
    d2 = _sq_dist(Y64, yy, scan, near)
    # u^2 on the scale of the expanded float64 distances, with room for their rounding
    # (a few ulps of ||y||^2 + ||b||^2) so each query's k nearest rows are all at most u^2
    u2 = np.maximum(np.partition(d2, k - 1, axis=1)[:, k - 1], 0.0) + 1e-12 \
        + 1e-13 * (yy + scan.vmax**2)
    u = np.sqrt(u2)
    # stage 2: rows within R_g of some centroid c_g hold every query's k nearest rows
    spread = np.sqrt(((Y64 - C64[label]) ** 2).sum(axis=1))
    radius = np.zeros(len(groups))
    np.maximum.at(radius, label, spread + u)
    limit = radius**2 - cc + margin  # (G,) on the D2 scale
    chosen = np.empty((n, k), dtype=np.int64)
    for chunk in np.array_split(np.arange(len(groups)), min(CHUNKS, len(groups))):
        inside = D2[chunk[0]] <= limit[chunk[0]]
        for g in chunk[1:]:
            inside |= D2[g] <= limit[g]
        ball = np.flatnonzero(inside)
        if ball.size < k:
            return None
        queries = np.concatenate([groups[g] for g in chunk])
        d2 = _sq_dist(Y64[queries], yy[queries], scan, ball)
        chosen[queries] = ball[_k_smallest(d2, u2[queries], k)]
    # the exact distances of the chosen rows, ascending
    diff = scan.rows64.take(chosen, axis=0)
    diff -= Y64[:, None, :]
    exact = np.einsum("qkd,qkd->qk", diff, diff)
    order = np.argsort(exact, axis=1, kind="stable")
    return np.take_along_axis(exact, order, axis=1), np.take_along_axis(chosen, order, axis=1)


def _k_smallest(d2: np.ndarray, bound: np.ndarray, k: int) -> np.ndarray:
    """(q, k) columns of the k smallest entries of each row of d2 (q, p).

    bound: (q,) a value at least each row's k-th smallest entry (from stage 1): only the few
    entries under it are ordered (a sort of ~k entries a row instead of a selection among p).
    """
    q, p = d2.shape
    if p <= k:
        return np.broadcast_to(np.arange(k), (q, k))
    qi, ci = np.nonzero(d2 <= bound[:, None])
    counts = np.bincount(qi, minlength=q)
    if counts.min() < k:  # the bound was beaten by rounding: select among all entries
        return np.argpartition(d2, k - 1, axis=1)[:, :k]
    if (counts == k).all():
        return ci.reshape(q, k)
    order = np.lexsort((d2[qi, ci], qi))  # by query, then by distance
    first = np.concatenate(([0], np.cumsum(counts)[:-1]))
    return ci[order[first[:, None] + np.arange(k)]]


def _sq_dist(Y: np.ndarray, yy: np.ndarray, scan: ScanData, cols: np.ndarray) -> np.ndarray:
    """(q, p) float64 squared distances of queries Y (q, d) float64 to the rows at cols (p,)."""
    d2 = (-2.0 * Y) @ scan.rows64.take(cols, axis=0).T
    d2 += yy[:, None]
    d2 += scan.norms.take(cols)[None, :]
    return d2


def _groups(Y: np.ndarray, n_groups: int) -> list[np.ndarray]:
    """Equal slabs of the queries along their main direction (the action moves the belief
    along a curve, so neighbouring candidates land in the same slab). Y: (Q, d) float64."""
    if n_groups <= 1:
        return [np.arange(Y.shape[0])]
    centred = Y - Y.mean(axis=0)
    direction = np.linalg.eigh(centred.T @ centred)[1][:, -1]
    order = np.argsort(centred @ direction, kind="stable")
    return np.array_split(order, n_groups)
