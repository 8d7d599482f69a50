"""Exact k nearest rows of a batch of queries by one scan of the corpus at group centroids.

The candidates of a control step spread in belief space about as far as their k-th neighbour
distance, and the beliefs (d_b = 20) have a high local dimension, so no single pool around
the batch centroid holds every query's neighbours, and the full (Q, N) distance matrix costs
Q N d_b multiply-adds and Q N memory traffic. Instead:

1. cut the Q queries into G groups of nearby queries (slabs along the batch's main direction)
   and compute the squared distance of each centroid c_g to every row: one (G, d_b + 1) x
   (d_b + 1, N) GEMM against the rows augmented with their squared norms;
2. per group, an upper bound u_i on each query's k-th neighbour distance: its k-th distance
   among the ~`POOL0` rows nearest c_g;
3. a row b with ||b - c_g|| > R_g = max_i (||y_i - c_g|| + u_i) is farther than u_i from every
   query i of the group (triangle inequality), so the rows within R_g of c_g hold each query's
   exact k nearest rows: rank them exactly (float64), `CHUNKS` consecutive groups at a time
   against the union of their balls (neighbouring balls overlap).

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
#: Consecutive groups whose balls are searched together (fewer, larger searches).
CHUNKS = 8


@dataclass
class ScanData:
    """What the scan needs of the M indexed rows, computed once per index.

    rows: (M, d) float32 (a view of the index storage); aug_t: (d + 1, M) float32, the rows
    transposed with their squared norms as the last line; norms: (M,) float64 ||v||^2;
    vmax: max ||v||.
    """

    rows: np.ndarray
    aug_t: np.ndarray
    norms: np.ndarray
    vmax: float

    @classmethod
    def of(cls, rows: np.ndarray) -> "ScanData":
        norms = np.einsum("md,md->m", rows, rows, dtype=np.float64)
        aug_t = np.empty((rows.shape[1] + 1, rows.shape[0]), dtype=np.float32)
        aug_t[:-1] = rows.T
        aug_t[-1] = norms
        return cls(rows, aug_t, norms, float(np.sqrt(norms.max(initial=0.0))))


def grouped_search(Y: np.ndarray, scan: ScanData, k: int, mask: np.ndarray | None = None):
    """Exact k nearest rows for every query, or None when the rounding margin was beaten.

    Y: (Q, d) float32 queries; mask: (M,) bool rows allowed (None: all), at least k of them.
    Returns (squared distances (Q, k) float64 ascending, positions (Q, k) int64 into the rows).
    """
    n, d = Y.shape
    V, M = scan.rows, scan.rows.shape[0]
    groups = _groups(Y, min(MAX_GROUPS, max(1, n // QUERIES_PER_GROUP)))
    C = np.stack([Y[g].mean(axis=0, dtype=np.float64) for g in groups]).astype(np.float32)
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
    step = max(1, POOL0 // 32)
    sample = D2[:, ::step]
    j = min(sample.shape[1] - 1, POOL0 // step)
    thresholds = np.partition(sample, j, axis=1)[:, j]
    near = np.flatnonzero((D2 <= thresholds[:, None]).any(axis=0)) \
        if np.isfinite(thresholds).all() else np.zeros(0, np.int64)
    if near.size < k:
        near = np.argpartition(D2.min(axis=0), k - 1)[:k]
    Y64 = Y.astype(np.float64)
    yy = (Y64 * Y64).sum(axis=1)
    d2 = _sq_dist(Y64, yy, V[near], scan.norms[near])
    u = np.sqrt(np.maximum(np.partition(d2, k - 1, axis=1)[:, k - 1], 0.0) + 1e-12)
    # stage 2: rows within R_g of some centroid c_g hold every query's k nearest rows
    label = np.empty(n, dtype=np.int64)
    for g, members in enumerate(groups):
        label[members] = g
    spread = np.sqrt(((Y64 - C64[label]) ** 2).sum(axis=1))
    radius = np.zeros(len(groups))
    np.maximum.at(radius, label, spread + u)
    limit = radius**2 - cc + margin  # (G,) on the D2 scale
    d2_out = np.empty((n, k))
    pos_out = np.empty((n, k), dtype=np.int64)
    for chunk in np.array_split(np.arange(len(groups)), min(CHUNKS, len(groups))):
        ball = np.flatnonzero((D2[chunk] <= limit[chunk, None]).any(axis=0))
        queries = np.concatenate([groups[g] for g in chunk])
        if ball.size < k:
            return None
        d2 = _sq_dist(Y64[queries], yy[queries], V[ball], scan.norms[ball])
        part = np.argpartition(d2, k - 1, axis=1)[:, :k] if ball.size > k else \
            np.broadcast_to(np.arange(k), (len(queries), k))
        rows = ball[part]
        diff = V[rows].astype(np.float64) - Y64[queries][:, None, :]
        exact = np.einsum("qkd,qkd->qk", diff, diff)
        order = np.argsort(exact, axis=1, kind="stable")
        d2_out[queries] = np.take_along_axis(exact, order, axis=1)
        pos_out[queries] = np.take_along_axis(rows, order, axis=1)
    return d2_out, pos_out


def _sq_dist(Y: np.ndarray, yy: np.ndarray, rows: np.ndarray, norms: np.ndarray) -> np.ndarray:
    """(q, p) float64 squared distances of queries Y (q, d) float64 to rows (p, d)."""
    d2 = Y @ rows.T.astype(np.float64)
    d2 *= -2.0
    d2 += yy[:, None]
    d2 += norms[None, :]
    return d2


def _groups(Y: np.ndarray, n_groups: int) -> list[np.ndarray]:
    """Equal slabs of the queries along their main direction (the action moves the belief
    along a curve, so neighbouring candidates land in the same slab)."""
    if n_groups <= 1:
        return [np.arange(Y.shape[0])]
    centred = Y.astype(np.float64) - Y.mean(axis=0, dtype=np.float64)
    direction = np.linalg.svd(centred, full_matrices=False)[2][0]
    order = np.argsort(centred @ direction, kind="stable")
    return np.array_split(order, n_groups)
