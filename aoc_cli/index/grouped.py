"""Exact k nearest rows of a batch of queries by one scan of the corpus at group centroids.

The candidates of a control step spread in belief space about as far as their k-th neighbour
distance, and the beliefs (d_b = 20) have a high local dimension, so no single pool around
the batch centroid holds every query's neighbours, and the full (Q, N) distance matrix costs
Q N d_b multiply-adds and Q N memory traffic. Instead:

1. cut the Q queries into G groups of nearby queries (slabs along the batch's main direction)
   and compute the squared distance of each centroid c_g to every row: one (N, d_b + 1) x
   (d_b + 1, G) GEMM of the rows augmented with their squared norms;
2. an upper bound u_i on each query's k-th neighbour distance: its k-th distance among the
   union of the ~`POOL0` rows nearest each centroid;
3. a row b with ||b - c_g|| > R_g = max_i (||y_i - c_g|| + u_i) is farther than u_i from every
   query i of the group (triangle inequality), and so is a row outside query i's annulus
   | ||b - c_g|| - ||y_i - c_g|| | <= u_i: one compiled pass over the rows (scan_kernels.py)
   ranks the rest of each group's ball against its queries, a float32 distance first (a
   filter with a bound on its rounding), the float64 distance of the rows within u_i, a heap
   of the k nearest per query.

The centroid distances are float32; the ball test adds a margin bounding their rounding error
(a sum of d_b + 2 products: gamma_{d_b+2} (||c|| + ||b||)^2, doubled), so a row may be kept
needlessly but never dropped wrongly.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from aoc_cli.index.scan_kernels import ball_knn, rows_under, sample_kth

#: Queries per group and the most groups: G = clip(Q // QUERIES_PER_GROUP, 1, MAX_GROUPS).
QUERIES_PER_GROUP = 6
MAX_GROUPS = 16
#: About this many rows nearest each centroid bound its queries' k-th distances.
POOL0 = 128
#: Columns of the strided sample of the centroid distances that sets the stage-1 thresholds.
SAMPLE = 4096


@dataclass
class ScanData:
    """What the scan needs of the M indexed rows, computed once per index.

    rows: (M, d) float32 (a view of the index storage); aug: (M, d + 1) float32, the rows
    with their squared norms as the last column; vmax: max ||v||;
    rows64: (M, d) float64 copy of the rows (the exact distances are taken from it).
    """

    rows: np.ndarray
    aug: np.ndarray
    vmax: float
    rows64: np.ndarray

    @classmethod
    def of(cls, rows: np.ndarray) -> "ScanData":
        rows64 = np.ascontiguousarray(rows, dtype=np.float64)
        norms = np.einsum("md,md->m", rows64, rows64)
        aug = np.empty((rows.shape[0], rows.shape[1] + 1), dtype=np.float32)
        aug[:, :-1] = rows
        aug[:, -1] = norms
        return cls(rows, aug, float(np.sqrt(norms.max(initial=0.0))), rows64)


def grouped_search(Y: np.ndarray, scan: ScanData, k: int, mask: np.ndarray | None = None):
    """Exact k nearest rows for every query, or None when the rounding margin was beaten.

    Y: (Q, d) float32 queries; mask: (M,) bool rows allowed (None: all), at least k of them.
    Returns (squared distances (Q, k) float64 ascending, positions (Q, k) int64 into the rows).
    """
    Y = np.ascontiguousarray(Y, dtype=np.float32)  # the bounds below assume float32 queries
    n, d = Y.shape
    M = scan.rows.shape[0]
    Y64 = Y.astype(np.float64)
    groups = _groups(Y64, min(MAX_GROUPS, max(1, n // QUERIES_PER_GROUP)))
    G = len(groups)
    sizes = np.array([g.size for g in groups])
    members = np.concatenate(groups)
    starts = np.concatenate(([0], np.cumsum(sizes)))
    label = np.repeat(np.arange(G), sizes)[np.argsort(members)]
    C = (np.add.reduceat(Y64[members], starts[:-1], axis=0) / sizes[:, None]).astype(np.float32)
    C_aug = np.empty((d + 1, G), dtype=np.float32)
    C_aug[:-1] = -2.0 * C.T
    C_aug[-1] = 1.0
    D2 = scan.aug @ C_aug  # (M, G): ||b||^2 - 2 c.b = ||b - c||^2 - ||c||^2
    if mask is not None:
        D2[~mask] = np.inf
    C64 = C.astype(np.float64)
    cc = (C64 * C64).sum(axis=1)
    eps = 2.0**-24
    gamma = (d + 2) * eps / (1.0 - (d + 2) * eps)
    margin = 2.0 * gamma * (np.sqrt(cc) + scan.vmax) ** 2
    # stage 1: about POOL0 rows nearest each centroid (threshold from a strided sample); each
    # query's k-th distance among their union bounds its k-th neighbour distance from above
    step = max(1, M // SAMPLE)
    j = min(-(-M // step) - 1, POOL0 // step)
    thresholds = sample_kth(D2, step, j)
    near = rows_under(D2, thresholds) if np.isfinite(thresholds).all() else np.zeros(0, np.int64)
    if near.size < k:
        near = np.argpartition(D2.min(axis=1), k - 1)[:k]
    yy = (Y64 * Y64).sum(axis=1)
    # their float32 distances, centred on the batch mean so the expansion does not cancel;
    # u^2 = the k-th of them plus a bound on their rounding (the centring's and the sum's:
    # 3e-6 (|y - c| + max |b - c|)^2 > (gamma_{d+2} + 2^-22) (...)^2), so each query's k
    # nearest rows are all at most u^2
    c32 = Y.mean(axis=0, dtype=np.float32)
    Yc = np.asarray(Y, dtype=np.float32) - c32
    Bc = scan.rows.take(near, axis=0) - c32
    bb = (Bc * Bc).sum(axis=1)
    yc = (Yc * Yc).sum(axis=1)
    d2 = Yc @ Bc.T
    d2 *= -2.0
    d2 += yc[:, None]
    d2 += bb[None, :]
    kth = np.partition(d2, k - 1, axis=1)[:, k - 1].astype(np.float64)
    reach = np.sqrt(yc.astype(np.float64)) + np.sqrt(float(bb.max()))
    u2 = np.maximum(kth, 0.0) + 3e-6 * reach**2 + 1e-12 + 1e-13 * (yy + scan.vmax**2)
    u = np.sqrt(u2)
    # stage 2: a row b with ||b - c_g|| > R_g = max_i (||y_i - c_g|| + u_i) is farther than u_i
    # from every query i of group g (triangle inequality), and so is a row outside query i's
    # own annulus | ||b - c_g|| - ||y_i - c_g|| | <= u_i: only the rest are ranked
    Yc = np.sqrt(((Y64 - C64[label]) ** 2).sum(axis=1))  # (Q,) ||y_i - c_g(i)||
    cg = cc[label]
    hi = (Yc + u) ** 2 - cg + margin[label]  # on the D2 scale
    inner = Yc - u
    lo = np.where(inner > 0, inner**2 - cg - margin[label], -np.inf)
    limit = np.full(G, -np.inf)
    np.maximum.at(limit, label, hi)
    rows = np.empty((n, k), dtype=np.int64)
    exact = np.empty((n, k))
    found = ball_knn(D2, limit, starts, members, hi, lo, Y64, u2, scan.rows64,
                     Y, scan.rows, k, rows, exact)
    if found < k:
        return None
    return exact, rows


def _groups(Y: np.ndarray, n_groups: int) -> list[np.ndarray]:
    """Equal slabs of the queries along their main direction (the action moves the belief
    along a curve, so neighbouring candidates land in the same slab). Y: (Q, d) float64."""
    if n_groups <= 1:
        return [np.arange(Y.shape[0])]
    centred = Y - Y.mean(axis=0)
    direction = np.linalg.eigh(centred.T @ centred)[1][:, -1]
    order = np.argsort(centred @ direction, kind="stable")
    return np.array_split(order, n_groups)
