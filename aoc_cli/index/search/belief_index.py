"""A FAISS index over the corpus beliefs: k nearest rows, row selection, re-sampling.

Entries of the FAISS index are *positions*; `row_of[position]` is the corpus row a position
stands for. A base index has one position per row (row_of = identity); a derived index built by
`resample` / `subsample` repeats or drops rows (a row rate of 4 = four copies of the row, 0.5 = a
seeded random half of the positions), so the same code answers "the k nearest rows of the re-weighted corpus"
(the paper's adaptivity experiment) with no retraining. Every answer is in corpus rows. The
FAISS structure of each kind and the input checks are in faiss_kinds.py.
"""

from __future__ import annotations

import json
import os
from dataclasses import asdict
from pathlib import Path

import faiss
import numpy as np

from aoc_cli.errors import AocError, call
from aoc_cli.index.search.config import IndexConfig
from aoc_cli.index.search.cells import CellData, cells_search
from aoc_cli.index.search.faiss_kinds import ADD_CHUNK, as_beliefs, as_queries, kind_of, new_faiss, storage_view
from aoc_cli.index.search.pooled import exact_among as _exact_among, pooled_search
from aoc_cli.threads import faiss_threads, single_threaded_blas
from aoc_cli.store.atomic import atomic_path, write_json, write_npy


class Selection:
    """A prepared row restriction: a FAISS ID selector over the index positions.

    Build it once (`BeliefIndex.select(rows_or_mask)`) and pass it to every search of a
    decision; preparing costs O(N), searching with it costs nothing extra.
    """

    def __init__(self, mask: np.ndarray):
        self.mask = mask  # (M,) bool over positions
        self.count = int(mask.sum())
        self._bits = np.packbits(mask, bitorder="little")
        self.selector = faiss.IDSelectorBitmap(mask.size, faiss.swig_ptr(self._bits))
        self.positions = np.flatnonzero(mask) if self.count <= 4096 else None


class BeliefIndex:
    """Nearest corpus beliefs of query beliefs, exact ("flat") or approximate ("hnsw", "ivf").

    beliefs: the (N, d) float32 corpus belief array the index was built from (kept by
    reference, e.g. a memory map; None after `load` without beliefs: vectors then come from the
    FAISS storage).
    """

    def __init__(
        self,
        index: faiss.Index,
        config: IndexConfig,
        kind: str,
        n_rows: int,
        row_of: np.ndarray | None = None,
        beliefs: np.ndarray | None = None,
    ):
        self.index = index
        self.config = config
        self.kind = kind
        self.n_rows = int(n_rows)
        self._row_of = None if row_of is None else np.asarray(row_of, dtype=np.int64)
        self.beliefs = beliefs
        self._store = storage_view(index, kind)
        self._cells: CellData | None = None  # built on the first batched search (flat, IVF)

    # ---------------------------------------------------------------- building
    @classmethod
    def build(cls, beliefs: np.ndarray, config: IndexConfig | None = None, **overrides) -> "BeliefIndex":
        """Index the (N, d) corpus beliefs. `overrides` set IndexConfig fields (e.g. kind="hnsw")."""
        config = config or IndexConfig()
        if overrides:
            config = IndexConfig.from_dict({**asdict(config), **overrides})
        beliefs = as_beliefs(beliefs)
        n_rows = beliefs.shape[0]
        if n_rows == 0:
            raise AocError("the corpus has no beliefs to index; compute beliefs for a non-empty corpus first")
        kind = config.resolved_kind(n_rows)
        with faiss_threads(config.threads):
            index = new_faiss(kind, beliefs, config)
            # IVF chunk by chunk: FAISS's temporaries (assignments, distances) stay the
            # chunk's size, a memory-mapped belief array is read once in order, and the lists
            # are the same
            step = ADD_CHUNK if kind == "ivf" else max(n_rows, 1)
            for a in range(0, n_rows, step):
                index.add(np.ascontiguousarray(beliefs[a:a + step]))
        return cls(index, config, kind, n_rows, None, beliefs)

    @property
    def dim(self) -> int:
        return int(self.index.d)

    @property
    def size(self) -> int:
        """Number of positions (index entries); equals n_rows for a base index."""
        return int(self.index.ntotal)

    @property
    def row_of(self) -> np.ndarray:
        """(size,) int64: the corpus row of every index position."""
        if self._row_of is None:
            return np.arange(self.size, dtype=np.int64)
        return self._row_of

    @property
    def derived(self) -> bool:
        return self._row_of is not None

    def vectors(self, positions: np.ndarray) -> np.ndarray:
        """(n, d) float32 beliefs stored at the given index positions."""
        positions = np.asarray(positions, dtype=np.int64)
        if self.beliefs is not None:
            rows = positions if self._row_of is None else self._row_of[positions]
            # take: a gather along the rows, ~2x faster than fancy indexing (also on a memmap)
            return np.asarray(np.take(self.beliefs, rows, axis=0), dtype=np.float32)
        if self._store is not None:
            return self._store[positions]
        if isinstance(self.index, faiss.IndexIVF) and self.index.direct_map.type == 0:
            self.index.make_direct_map()
        return self.index.reconstruct_batch(positions)

    # ---------------------------------------------------------------- selection
    def select(self, selection) -> Selection:
        """Prepare a row restriction: a boolean mask over corpus rows (N,) or an array of rows."""
        if isinstance(selection, Selection):
            if selection.mask.size != self.size:
                raise AocError("this selection was prepared for another index; prepare it with this index's select()")
            return selection
        sel = np.asarray(selection)
        if sel.dtype == bool:
            if sel.shape != (self.n_rows,):
                raise AocError(
                    f"row mask has shape {sel.shape}, the corpus has {self.n_rows} rows; pass one flag per row"
                )
            rows_mask = sel
        else:
            if sel.size and not np.issubdtype(sel.dtype, np.integer):
                raise AocError("a selection is a boolean row mask or an array of integer row ids")
            sel = sel.astype(np.int64).ravel()
            if sel.size and (sel.min() < 0 or sel.max() >= self.n_rows):
                raise AocError(f"selected row ids must lie in [0, {self.n_rows}); check the selection")
            rows_mask = np.zeros(self.n_rows, dtype=bool)
            rows_mask[sel] = True
        mask = rows_mask if self._row_of is None else rows_mask[self._row_of]
        prepared = Selection(np.ascontiguousarray(mask))
        if prepared.count == 0:
            raise AocError("the selection leaves no corpus rows in the index; select at least one row")
        return prepared

    def _params(self, selection: Selection | None, k: int):
        sel = None if selection is None else selection.selector
        if self.kind == "hnsw":
            params = faiss.SearchParametersHNSW(efSearch=max(self.config.hnsw_ef_search, k))
        elif self.kind == "ivf":
            params = faiss.SearchParametersIVF(nprobe=self.config.ivf_nprobe)
        else:
            params = faiss.SearchParameters()
        if sel is not None:
            params.sel = sel
        return params

    # ---------------------------------------------------------------- search
    def search(self, queries: np.ndarray, k: int, selection=None) -> tuple[np.ndarray, np.ndarray]:
        """The k nearest corpus rows of each query.

        queries: (Q, d) beliefs. selection: None, a row mask (N,) bool, an array of rows, or a
        prepared `Selection`. Returns distances (Q, k) float64, Euclidean, ascending, and rows
        (Q, k) int64 corpus rows; when fewer than k rows are available the tail is padded with
        inf / -1. A batch (Q >= 2) of a flat or IVF-Flat index is searched exactly, cell by
        cell with distance bounds (cells.py: k-means cells of a flat index, the inverted lists
        of an IVF); a batch of an HNSW index is served by one search at its centroid when
        that answer is certified (see IndexConfig.pool_factor), the rest by groups and then
        query by query (pooled.py); a single query by FAISS (approximate for IVF and HNSW).
        """
        Y = as_queries(queries, self.dim)
        if k < 1:
            raise AocError(f"k must be at least 1 (got {k}); ask for one or more neighbours")
        sel = None if selection is None else self.select(selection)
        available = self.size if sel is None else sel.count
        kk = min(int(k), available)
        dist = np.full((Y.shape[0], int(k)), np.inf)
        pos = np.full((Y.shape[0], int(k)), -1, dtype=np.int64)
        with single_threaded_blas(), faiss_threads(self.config.threads):
            if sel is not None and sel.positions is not None:
                # a small selection: exact over the selected rows, whatever the kind
                d2, p = _exact_among(Y, self.vectors(sel.positions), kk)
                dist[:, :kk], pos[:, :kk] = d2, sel.positions[p]
            elif Y.shape[0] >= 2 and self.cells() is not None:
                dist[:, :kk], pos[:, :kk] = cells_search(Y, self.cells(), kk,
                                                         None if sel is None else sel.mask)
            elif Y.shape[0] >= 2:
                dist[:, :kk], pos[:, :kk] = pooled_search(self, Y, kk, sel, available)
            else:
                dist[:, :kk], pos[:, :kk] = self._direct(Y, kk, sel)
        rows = pos if self._row_of is None else np.where(pos >= 0, self._row_of[np.maximum(pos, 0)], -1)
        return np.sqrt(np.maximum(dist, 0.0)), rows

    def search_exact(self, queries: np.ndarray, k: int, selection) -> tuple[np.ndarray, np.ndarray]:
        """``search``'s answer computed exactly among every selected position (each one read):
        what a restricted search of an approximate index (IVF, HNSW) falls back to when it
        found fewer than k rows, e.g. a stratum far from the query (aoc_cli.index.search.strata)."""
        Y = as_queries(queries, self.dim)
        sel = self.select(selection)
        positions = np.flatnonzero(sel.mask)
        kk = min(int(k), len(positions))
        dist = np.full((Y.shape[0], int(k)), np.inf)
        pos = np.full((Y.shape[0], int(k)), -1, dtype=np.int64)
        with single_threaded_blas():
            d2, p = _exact_among(Y, self.vectors(positions), kk)
        dist[:, :kk], pos[:, :kk] = d2, positions[p]
        rows = pos if self._row_of is None else np.where(pos >= 0, self._row_of[np.maximum(pos, 0)], -1)
        return np.sqrt(np.maximum(dist, 0.0)), rows

    def _direct(self, Y: np.ndarray, k: int, sel: Selection | None) -> tuple[np.ndarray, np.ndarray]:
        with faiss_threads(1 if Y.shape[0] < 8 else self.config.threads):
            D, I = self.index.search(Y, k, params=self._params(sel, k))
        D = np.where(I >= 0, D.astype(np.float64), np.inf)
        return D, I

    def row_beliefs(self, rows: np.ndarray) -> np.ndarray | None:
        """(n, d) float32 beliefs of the corpus rows (n,) from the batch search's cells, the
        same values as the belief array's (the index stores them as given); None when the index
        has no cells (yet) or is derived (a row may be at several positions or none)."""
        if self.derived or self._cells is None or self._cells.size != self.size:
            return None
        return self._cells.gather(rows)

    def cells(self) -> CellData | None:
        """The rows cell by cell for the exact batch search (cells.py), built at the first call:
        k-means cells of a flat index, the inverted lists of an IVF-Flat (L2) one; None for
        any other index (HNSW: batches by pooled.py)."""
        if self._cells is None or self._cells.size != self.size:
            if self.kind == "flat" and self._store is not None:
                self._cells = CellData.kmeans(self._store, self.config.seed)
            elif isinstance(self.index, faiss.IndexIVFFlat) and self.index.metric_type == faiss.METRIC_L2:
                self._cells = CellData.ivf(self.index, self.config.seed)
        return self._cells

    # ---------------------------------------------------------------- adaptivity
    def resample(self, row_rates, seed: int | None = None) -> "BeliefIndex":
        """A derived index where corpus row c appears row_rates[c] times.

        row_rates: a scalar or (N,) non-negative floats over corpus rows, applied to every
        position of this index. The integer part gives copies; of the positions sharing a
        fractional part f, exactly round(f * n_f) get one more copy, chosen at random (seeded).
        So 4 = four copies, 1 = unchanged, 0.5 = a random half of the positions, 0 = dropped.

        The index knows rows, not episodes: a fraction here is a *row rate*, sampling single
        positions. The session's *episode rates* (``aoc index --episode-rate policy=pi1:0.5``)
        keep whole episodes; :func:`aoc_cli.rows.episode_multiplicity` turns them into integer
        counts per row before they reach this method.
        """
        mult = np.asarray(row_rates, dtype=np.float64)
        if mult.ndim == 0:
            mult = np.full(self.n_rows, float(mult))
        if mult.shape != (self.n_rows,):
            raise AocError(f"row_rates needs one value per corpus row ({self.n_rows}); got shape {mult.shape}")
        if not np.all(np.isfinite(mult)) or (mult < 0).any():
            raise AocError("row_rates must be finite and non-negative; fix the re-sampling weights")
        per_pos = mult[self.row_of]
        base = np.floor(per_pos)
        frac = np.round(per_pos - base, 12)
        counts = base.astype(np.int64)
        rng = np.random.default_rng(self.config.seed if seed is None else seed)
        for f in np.unique(frac[frac > 0]):
            members = np.flatnonzero(frac == f)
            extra = int(round(f * members.size))
            counts[rng.choice(members, size=extra, replace=False)] += 1
        positions = np.repeat(np.arange(self.size, dtype=np.int64), counts)
        if positions.size == 0:
            raise AocError("re-sampling leaves no corpus rows; give some rows a positive row rate")
        vectors = np.ascontiguousarray(self.vectors(positions))
        with faiss_threads(self.config.threads):
            if self.kind == "ivf":
                index = faiss.clone_index(self.index)
                index.reset()  # keeps the trained coarse quantiser: no re-training
            else:
                index = new_faiss(self.kind, vectors, self.config)
            index.add(vectors)
        row_of = self.row_of[positions]
        return BeliefIndex(index, self.config, self.kind, self.n_rows, row_of, self.beliefs)

    def subsample(self, fraction, seed: int | None = None) -> "BeliefIndex":
        """A derived index keeping a seeded random fraction of rows (scalar or (N,) in [0, 1])."""
        frac = np.asarray(fraction, dtype=np.float64)
        if (frac < 0).any() or (frac > 1).any():
            raise AocError("sub-sampling fractions must lie in [0, 1]; use resample for copies")
        return self.resample(frac, seed=seed)

    # ---------------------------------------------------------------- persistence
    def save(self, path: str | os.PathLike) -> None:
        """Write the FAISS index to `path`, its config to `path`.json (and the row map of a
        derived index to `path`.rows.npy), each atomically (temp file + os.replace)."""
        path = Path(path)
        path.parent.mkdir(parents=True, exist_ok=True)
        with atomic_path(path) as tmp:
            faiss.write_index(self.index, str(tmp))
        meta = {
            "kind": self.kind,
            "n_rows": self.n_rows,
            "dim": self.dim,
            "size": self.size,
            "derived": self.derived,
            "config": asdict(self.config),
        }
        write_json(f"{path}.json", meta)
        rows_path = Path(f"{path}.rows.npy")
        if self.derived:
            write_npy(rows_path, self._row_of)
        elif rows_path.exists():
            rows_path.unlink()

    @classmethod
    def load(cls, path: str | os.PathLike, beliefs: np.ndarray | None = None) -> "BeliefIndex":
        """Read an index written by `save`. beliefs: the corpus belief array (optional)."""
        path = Path(path)
        if not path.exists():
            raise AocError(f"no index at {path}; build it first ({call('build_index')})")
        index = faiss.read_index(str(path))
        meta_path = Path(f"{path}.json")
        meta = json.loads(meta_path.read_text()) if meta_path.exists() else {}
        config = IndexConfig.from_dict(meta.get("config", {}), strict=False)
        kind = meta.get("kind") or kind_of(index)
        rows_path = Path(f"{path}.rows.npy")
        row_of = np.load(rows_path) if meta.get("derived") and rows_path.exists() else None
        n_rows = int(meta.get("n_rows", index.ntotal))
        if beliefs is not None:
            beliefs = as_beliefs(beliefs)
            if beliefs.shape != (n_rows, index.d):
                raise AocError(
                    f"beliefs have shape {beliefs.shape} but the index was built on ({n_rows}, {index.d}); rebuild the index"
                )
        return cls(index, config, kind, n_rows, row_of, beliefs)
