"""Configuration of the nearest-neighbour index over corpus beliefs."""

from __future__ import annotations

import math
from dataclasses import dataclass

from aoc_cli.settings import Settings, setting

KINDS = ("auto", "flat", "hnsw", "ivf")


@dataclass(frozen=True)
class IndexConfig(Settings):
    """How the k nearest corpus beliefs of a query are found (step 1 of the decomposition).

    The index answers  N_k(y) = the k corpus rows c minimising ||b^c - y||_2  (the paper uses
    k = 2(d_b + 1) neighbours, docs/design.md "The method, precisely", step 1).

    kind: "flat" is exact brute force; "hnsw" (graph) and "ivf" (inverted lists) are approximate
        for a single query; a batch of queries (a control step's candidates) is searched
        exactly for flat and IVF-Flat (cell by cell with distance bounds, cells.py: an IVF's
        lists are its cells). "auto" picks flat up to `auto_flat_max` rows and ivf beyond:
        IVF-Flat keeps the index at ~1.1x the belief array (HNSW with M = 32 needs ~4x).
    hnsw_m, hnsw_ef_construction, hnsw_ef_search: graph degree and beam widths (the search beam
        is raised to at least the number of neighbours asked for).
    ivf_nlist: number of inverted lists (0: sqrt(N) rounded down to a power of two, at most 4096);
        ivf_nprobe: lists visited per query; ivf_train_max: rows used to train the coarse quantiser.
    pool_factor, pool_min: batched search of an HNSW index (a flat or IVF-Flat index answers a
        batch exactly by the cell search of ``aoc_cli/index/search/cells.py`` instead). The Q queries of
        one control step lie close together, so the index is searched once, at their centroid c, for k' = max(pool_factor * k,
        pool_min) rows. A row outside that pool is at least d_k'(c) - ||y_i - c|| from query i
        (triangle inequality), so query i's k nearest rows inside the pool are its exact k
        nearest whenever its k-th distance is below that bound ("certified"). Uncertified
        queries are searched one by one. With an approximate kind the pool is as good as the
        index's own answer for c.
    threads: FAISS OpenMP threads (0: leave FAISS's default).
    seed: seeds k-means training and the random parts of re-sampling.
    """

    label = "index"

    kind: str = setting("auto", choices=KINDS,
                        help="The nearest-neighbour index: flat (exact), hnsw (graph), ivf "
                             "(inverted lists); auto: flat up to auto_flat_max rows, else ivf.")
    auto_flat_max: int = setting(200_000, bounds=">= 0",
                                 help="The largest corpus (rows) kind auto indexes flat.")
    hnsw_m: int = setting(32, bounds=">= 2", help="HNSW graph degree.")
    hnsw_ef_construction: int = setting(64, bounds=">= 1", help="HNSW beam width when built.")
    hnsw_ef_search: int = setting(128, bounds=">= 1", help="HNSW beam width when searched.")
    ivf_nlist: int = setting(0, bounds=">= 0",
                             help="IVF inverted lists (0: sqrt(N) rounded down to a power of "
                                  "two, at most 4096).")
    ivf_nprobe: int = setting(16, bounds=">= 1", help="IVF lists visited per query.")
    ivf_train_max: int = setting(200_000, bounds=">= 1",
                                 help="Rows used to train the IVF coarse quantiser.")
    pool_factor: float = setting(4.0, bounds="> 0",
                                 help="Batched HNSW search: the pool is pool_factor k rows.")
    pool_min: int = setting(128, bounds=">= 1",
                            help="Batched HNSW search: the pool has at least this many rows.")
    threads: int = setting(0, bounds=">= 0", help="FAISS OpenMP threads (0: FAISS's default).")
    seed: int = setting(0, help="Seed of k-means training and of re-sampling.")

    def resolved_kind(self, n_rows: int) -> str:
        """The concrete kind used for a corpus of n_rows rows."""
        if self.kind != "auto":
            return self.kind
        if n_rows <= self.auto_flat_max:
            return "flat"
        return "ivf"

    def nlist(self, n_rows: int) -> int:
        """Inverted lists for IVF: the configured number, or about sqrt(N)."""
        if self.ivf_nlist > 0:
            return min(self.ivf_nlist, max(1, n_rows))
        target = math.sqrt(max(n_rows, 1))
        return int(min(4096, max(1, 2 ** math.floor(math.log2(max(target, 1.0))))))
