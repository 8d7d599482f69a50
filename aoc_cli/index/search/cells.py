"""Exact k nearest rows of a batch of queries by a search of cells with distance bounds.

The indexed rows are split into L cells (k-means cells for a flat index, the inverted lists of
an IVF-Flat index), each with a centre z_l. Stored once per index (``CellData``): the rows cell
after cell, each cell's rows ascending by rho = ||b - z_l||, each cell's radius (the largest
rho), and every row's first ``HEAD`` principal coordinates (the beliefs' variance is
concentrated in a few directions: on pendulum corpora 99 % in the first three). For a query y
and its current k-th distance T (the top of its heap of the k best so far):

* a cell with ||y - z_l|| - radius_l > T holds no row within T of y;
* a row with |rho - ||y - z_l||| > T is farther than T (triangle inequality); the rows of a
  cell are sorted by rho, so the rows left are one slice found by a binary search;
* a row whose distance to y along the first HEAD principal axes exceeds T is farther than T
  (a projection shortens distances);
* then a float32 distance filters, and the float64 squared distance from the differences,
  summed in order, ranks the rows left in a heap ordered by (distance, position).

Each query visits its cells nearest centre first (T falls fast). The answer is every query's
exact k nearest rows, ties by the lower index position, whatever the cells and axes are (they
only decide how much is skipped). Every bound carries a margin above its rounding (the
query-centre distances come from a float64 GEMM with a bound on its error; the principal
coordinates are float32 with a bound on theirs), so a row is never dropped wrongly.

Shapes: Y (Q, d) float32 queries; results (Q, k) squared distances float64 ascending and
positions int64.
"""

from __future__ import annotations

from dataclasses import dataclass

import faiss
import numba
import numpy as np
from numba.typed import List

from aoc_cli.index.search.scan_kernels import replace_top, sort_heaps, sq32, up32

#: Principal coordinates kept per row for the projection bound.
HEAD = 4
#: Rows per block when rows are read, rotated or assigned (bounds the temporaries).
BLOCK = 1 << 18
#: Queries searched at once (bounds the (Q, L) query-centre distance bounds).
QUERY_CHUNK = 1024
#: Relative slack of the triangle-inequality tests (far above the rounding of rho, T and the
#: centre bounds; a larger slack only keeps more rows).
SLACK = 1e-9


@dataclass
class CellData:
    """The rows of an index cell after cell (built once per index; M rows, L cells, d dims).

    centres: (L, d) float64; offsets: (L + 1,) int64, cell l holds the stored rows
    offsets[l] <= m < offsets[l + 1]; rows / ids: typed lists of L arrays, cell l's rows
    (n_l, d) float32 and their index positions (n_l,) int64 (for an IVF, FAISS's own inverted
    lists, sorted in place: no copy); rho: (M,) float64 ||row - centre||, ascending within a
    cell; radius: (L,) float64 largest rho of each cell; mean: (d,) float64 and axes: (d, HEAD)
    float64 orthonormal principal axes; head: (M, HEAD) float32 the rows' coordinates
    (row - mean) @ axes; reach: float64, max ||head row||; owner: what holds the rows' memory.
    """

    centres: np.ndarray
    offsets: np.ndarray
    rows: List
    ids: List
    rho: np.ndarray
    radius: np.ndarray
    mean: np.ndarray
    axes: np.ndarray
    head: np.ndarray
    reach: float
    owner: object = None
    _where: np.ndarray | None = None  # (M,) stored row of each position, built by gather

    @property
    def size(self) -> int:
        """M, the rows stored."""
        return int(self.offsets[-1])

    def gather(self, positions: np.ndarray) -> np.ndarray:
        """(n, d) float32 rows stored at the given index positions (n,) (all in [0, M)), read
        from the cells (not from a memory-mapped belief array: its pages stay out of memory)."""
        if self._where is None:
            where = np.empty(self.size, dtype=np.int64)  # position -> stored row
            for l in range(len(self.ids)):
                where[self.ids[l]] = np.arange(self.offsets[l], self.offsets[l + 1])
            self._where = where
        positions = np.ascontiguousarray(positions, dtype=np.int64).reshape(-1)
        out = np.empty((positions.shape[0], self.centres.shape[1]), dtype=np.float32)
        _gather(self.rows, self.offsets, self._where, positions, out)
        return out

    def stored(self) -> tuple[np.ndarray, np.ndarray]:
        """(rows (M, d) float32, ids (M,) int64) cell after cell, as one copy (for checks)."""
        d = self.centres.shape[1]
        if not len(self.rows):
            return np.empty((0, d), np.float32), np.empty(0, np.int64)
        return np.concatenate(list(self.rows)), np.concatenate(list(self.ids))

    @classmethod
    def kmeans(cls, rows: np.ndarray, seed: int = 0) -> "CellData":
        """k-means cells of the (M, d) float32 rows of a flat index (about sqrt(M) / 2 cells,
        trained on a sample; the cells decide the speed, never the answer). The rows are
        copied in cell order."""
        M, d = rows.shape
        L = int(min(4096, 2 ** int(np.floor(np.log2(max(np.sqrt(M) / 2, 1.0))))))
        rng = np.random.default_rng(seed)
        sample = np.ascontiguousarray(rows[np.sort(rng.choice(M, min(M, 256 * L), replace=False))])
        km = faiss.Kmeans(d, L, niter=10, seed=seed, max_points_per_centroid=256)
        km.train(sample)
        assign = np.empty(M, dtype=np.int64)
        for a in range(0, M, BLOCK):
            assign[a:a + BLOCK] = km.index.search(np.ascontiguousarray(rows[a:a + BLOCK]), 1)[1][:, 0]
        order = np.argsort(assign, kind="stable")
        sizes = np.bincount(assign, minlength=L)
        offsets = np.concatenate(([0], np.cumsum(sizes))).astype(np.int64)
        copy = np.ascontiguousarray(rows[order], dtype=np.float32)
        ids = order.astype(np.int64)
        cells = [(copy[offsets[l]:offsets[l + 1]], ids[offsets[l]:offsets[l + 1]]) for l in range(L)]
        return cls._sorted(np.asarray(km.centroids, np.float64), cells, seed, (copy, ids))

    @classmethod
    def ivf(cls, index: faiss.IndexIVFFlat, seed: int = 0) -> "CellData":
        """The cells of an IVF-Flat (L2) index: its inverted lists around its coarse centroids.
        The lists are read in place (FAISS's arrays: no copy of the rows) and each list is
        sorted in place by (rho, position): FAISS's own search scans whole lists, so the order
        inside a list changes none of its answers but the order of exactly tied distances."""
        inv = faiss.downcast_InvertedLists(faiss.extract_index_ivf(index).invlists)
        in_place = isinstance(inv, faiss.ArrayInvertedLists)  # else (on disk...) a copy
        L, d = index.nlist, index.d
        centres = np.ascontiguousarray(index.quantizer.reconstruct_n(0, L), dtype=np.float64)
        cells = []
        for l in range(L):
            n = int(inv.list_size(l))
            if n == 0:
                cells.append((np.empty((0, d), np.float32), np.empty(0, np.int64)))
                continue
            codes = faiss.rev_swig_ptr(inv.get_codes(l), n * index.code_size)
            vecs = codes.view(np.float32).reshape(n, d)
            own = faiss.rev_swig_ptr(inv.get_ids(l), n).view(np.int64)
            cells.append((vecs, own) if in_place else (vecs.copy(), own.copy()))
        return cls._sorted(centres, cells, seed, index)

    @classmethod
    def _sorted(cls, centres: np.ndarray, cells: list, seed: int, owner) -> "CellData":
        """Sort every cell's (rows, ids) in place by (rho, position) and add the rest."""
        L = centres.shape[0]
        sizes = np.array([len(ids) for _, ids in cells], dtype=np.int64)
        offsets = np.concatenate(([0], np.cumsum(sizes))).astype(np.int64)
        rho = np.empty(int(offsets[-1]))
        radius = np.zeros(L)
        rows_list, ids_list = List(), List()
        for l, (vecs, own) in enumerate(cells):
            if len(own):
                diff = vecs.astype(np.float64) - centres[l]
                r = np.sqrt(np.einsum("md,md->m", diff, diff))
                order = np.lexsort((own, r))
                vecs[:] = vecs[order]
                own[:] = own[order]
                rho[offsets[l]:offsets[l + 1]] = r[order]
                radius[l] = r.max()
            rows_list.append(vecs)
            ids_list.append(own)
        mean, axes = _principal_axes(cells, seed)
        head = np.empty((int(offsets[-1]), axes.shape[1]), dtype=np.float32)
        for l, (vecs, _) in enumerate(cells):
            head[offsets[l]:offsets[l + 1]] = (vecs.astype(np.float64) - mean) @ axes
        reach = float(np.sqrt(np.einsum("mh,mh->m", head, head).max(initial=0.0)))
        return cls(centres, offsets, rows_list, ids_list, rho, radius, mean, axes, head, reach,
                   owner)


def cells_search(Y: np.ndarray, cells: CellData, k: int,
                 allowed: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Exact k nearest index positions of every query (see the module docstring).

    Y: (Q, d) queries (used as float32); allowed: (P,) bool over index positions (None: all),
    with at least k allowed. Returns (squared distances (Q, k) float64 ascending, positions
    (Q, k) int64); ties by the lower position. Queries are searched QUERY_CHUNK at a time (the
    (Q, L) query-centre bounds stay small for a large Q).
    """
    if Y.shape[0] > QUERY_CHUNK:
        parts = [cells_search(Y[a:a + QUERY_CHUNK], cells, k, allowed)
                 for a in range(0, Y.shape[0], QUERY_CHUNK)]
        return np.concatenate([p[0] for p in parts]), np.concatenate([p[1] for p in parts])
    Y32 = np.ascontiguousarray(Y, dtype=np.float32)
    Y64 = Y32.astype(np.float64)
    Z = cells.centres
    yy = np.einsum("qd,qd->q", Y64, Y64)
    zz = np.einsum("ld,ld->l", Z, Z)
    g = yy[:, None] + zz[None, :] - 2.0 * (Y64 @ Z.T)  # (Q, L) ||y - z||^2 by expansion
    # its error is below gamma_{d+2} (|y| + |z|)^2 whatever BLAS's summation order
    err = (Y64.shape[1] + 8) * 2.0**-52 * (np.sqrt(yy)[:, None] + np.sqrt(zz)[None, :]) ** 2
    lo = np.sqrt(np.maximum(g - err, 0.0))
    hi = np.sqrt(g + err)
    yh = (Y64 - cells.mean) @ cells.axes  # (Q, HEAD)
    # the float32 principal coordinates of a row and of a query are each within 2^-24 of
    # their float64 values (relatively) plus the rotation's float64 rounding: their
    # difference's norm is off by at most 2^-22 (reach + |yh|) (margin doubled)
    shift = 2.0**-22 * (cells.reach + np.sqrt(np.einsum("qh,qh->q", yh, yh))) + 1e-30
    mask = np.zeros(0, dtype=np.bool_) if allowed is None else np.ascontiguousarray(allowed)
    d2 = np.empty((Y32.shape[0], k))
    pos = np.empty((Y32.shape[0], k), dtype=np.int64)
    # searched along the batch's main direction (three power iterations from its farthest
    # query: the order only decides how tight each query's start bound is)
    centred = Y64 - Y64.mean(axis=0)
    v = centred[np.argmax(np.einsum("qd,qd->q", centred, centred))]
    for _ in range(3):
        v = centred.T @ (centred @ v)
    seq = np.argsort(centred @ v, kind="stable")
    cells_knn(Y32, Y64, seq, lo, hi, yh.astype(np.float32), shift, cells.radius, cells.offsets,
              cells.rho, cells.rows, cells.head, cells.ids, mask, k, pos, d2)
    return d2, pos


def _principal_axes(cells: list, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """(mean (d,), axes (d, HEAD)) of the cells' rows (from a sample of at most ~65,536)."""
    total = sum(len(ids) for _, ids in cells)
    rng = np.random.default_rng(seed)
    keep = min(1.0, (1 << 16) / max(total, 1))
    sample = np.concatenate([vecs[rng.random(len(vecs)) < keep] for vecs, _ in cells])
    sample = sample.astype(np.float64)
    mean = sample.mean(axis=0)
    centred = sample - mean
    vectors = np.linalg.eigh(centred.T @ centred)[1][:, ::-1]
    return mean, np.ascontiguousarray(vectors[:, :min(HEAD, sample.shape[1])])


@numba.njit(cache=True, nogil=True)
def cells_knn(Y32, Y, seq, lo, hi, YH, shift, radius, offsets, rho, rows, head, ids, allowed,
              k, out_pos, out_d2):  # pragma: no cover - compiled
    """Fill out_pos (Q, k) and out_d2 (Q, k) with every query's exact k nearest rows.

    Y32: (Q, d) float32 queries, Y the same in float64; seq: (Q,) the order in which they are
    searched (neighbours next to each other: each starts from the bound its predecessor
    gives); lo, hi: (Q, L) bounds of ||y_i - z_l||; YH: (Q, H) float32 principal coordinates
    of the queries and shift (Q,) the bound on their and the rows' rounding; radius (L,),
    offsets (L + 1,), rho (M,), rows (typed list of L (n_l, d) float32), head (M, H) float32,
    ids (typed list of L (n_l,) int64): the cells (CellData); allowed: (P,) bool over positions, or empty for all.
    """
    Q, d = Y.shape
    L = lo.shape[1]
    check = allowed.shape[0] > 0
    hd = np.empty(k)
    hr = np.empty(k, dtype=np.int64)
    size = 0
    for l in range(L):
        size = max(size, offsets[l + 1] - offsets[l])
    buf = np.empty(size, dtype=np.float32)
    prev, reach_prev = -1, np.inf
    for j in range(Q):
        i = seq[j]
        # the previous query's k rows are within T_prev + ||y - y_prev|| of this query
        start = np.inf
        if prev >= 0 and reach_prev < np.inf:
            step = 0.0
            for t in range(d):
                diff = Y[i, t] - Y[prev, t]
                step = step + diff * diff
            start = (reach_prev + np.sqrt(step)) * (1.0 + SLACK) + 1e-30
        for attempt in range(2):  # a second pass without the start bound (never needed)
            hd[:] = np.inf
            hr[:] = -1
            _visit(Y32[i], Y[i], lo[i], hi[i], YH[i], shift[i], start if attempt == 0 else np.inf,
                   radius, offsets, rho, rows, head, ids, allowed, check, hd, hr, buf)
            if hd[0] < np.inf:
                break
        prev, reach_prev = i, np.sqrt(hd[0])
        sort_heaps(hd.reshape(1, k), hr.reshape(1, k), out_d2[i:i + 1], out_pos[i:i + 1])


@numba.njit(cache=True, nogil=True)
def _visit(y32, y, lo, hi, yh, shift, T, radius, offsets, rho, rows, head, ids, allowed, check,
           hd, hr, buf):  # pragma: no cover - compiled
    """One query: its cells nearest centre first, the rows each bound leaves ranked into the
    heap (hd, hr); T: a bound on its k-th distance known beforehand (inf: none)."""
    d = y.shape[0]
    top, toph = _bounds(T, shift)
    if T == np.inf:
        order = np.argsort(lo)
    else:  # only the cells the bound leaves, sorted (a few of them)
        order = np.flatnonzero(lo - radius <= T + SLACK * (hi + T) + 1e-30)
        order = order[np.argsort(lo[order])]
    for j in range(order.shape[0]):
        l = order[j]
        a0 = offsets[l]
        a, b = a0, offsets[l + 1]
        slack = SLACK * (hi[l] + T) + 1e-30
        if a == b or lo[l] - radius[l] > T + slack:
            continue  # no row of this cell is within T
        V, I = rows[l], ids[l]
        if T < np.inf:  # the rows with lo - T <= rho <= hi + T: binary searches
            b = a + np.searchsorted(rho[a:b], hi[l] + T + slack, side="right")
            a = a + np.searchsorted(rho[a:b], lo[l] - T - slack)
        # their distances along the principal axes (vectorised), a lower bound
        _head_dists(head, yh, a, b, buf)
        for m in range(a, b):
            if buf[m - a] > toph:
                continue
            p = I[m - a0]
            if check and not allowed[p]:
                continue
            # float32 (all terms >= 0: within (d + 2) 2^-24 of the exact value,
            # relatively) filters; the float64 distance, summed in order, ranks
            if sq32(V[m - a0], y32) > top:
                continue
            e = 0.0
            for t in range(d):
                diff = np.float64(V[m - a0, t]) - y[t]
                e = e + diff * diff
            if e < hd[0] or (e == hd[0] and p < hr[0]):
                replace_top(hd, hr, e, p)
                if hd[0] < np.inf:
                    T = min(T, np.sqrt(hd[0]))
                    slack = SLACK * (hi[l] + T) + 1e-30
                    top, toph = _bounds(T, shift)


@numba.njit(cache=True, nogil=True)
def _bounds(T, shift):  # pragma: no cover - compiled
    """float32 thresholds not below T^2 and (T + shift)^2 (with the float32 filters' margin)."""
    if T == np.inf:
        return np.float32(np.inf), np.float32(np.inf)
    return up32(T * T * (1.0 + 1e-5) + 1e-30), up32((T + shift) ** 2 * (1.0 + 1e-5) + 1e-30)


@numba.njit(cache=True, nogil=True, fastmath={"reassoc", "contract"})
def _head_dists(head, yh, a, b, out):  # pragma: no cover - compiled
    """out[m - a] = ||head[m] - yh||^2 in float32 for the rows a <= m < b (any order)."""
    H = head.shape[1]
    for m in range(a, b):
        e = np.float32(0.0)
        for t in range(H):
            x = head[m, t] - yh[t]
            e += x * x
        out[m - a] = e


@numba.njit(cache=True, nogil=True)
def _gather(rows, offsets, where, positions, out):  # pragma: no cover - compiled
    """out[i] = the stored row of positions[i] (rows: typed list of the cells' arrays)."""
    for i in range(positions.shape[0]):
        m = where[positions[i]]
        l = np.searchsorted(offsets, m, side="right") - 1
        out[i] = rows[l][m - offsets[l]]
