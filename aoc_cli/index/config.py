"""Configuration of the nearest-neighbour index over corpus beliefs."""

from __future__ import annotations

import math
from dataclasses import dataclass, fields

from aoc_cli.errors import AocError

KINDS = ("auto", "flat", "hnsw", "ivf")


@dataclass
class IndexConfig:
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
        batch exactly by the cell search of ``aoc_cli/index/cells.py`` instead). The Q queries of
        one control step lie close together, so the index is searched once, at their centroid c, for k' = max(pool_factor * k,
        pool_min) rows. A row outside that pool is at least d_k'(c) - ||y_i - c|| from query i
        (triangle inequality), so query i's k nearest rows inside the pool are its exact k
        nearest whenever its k-th distance is below that bound ("certified"). Uncertified
        queries are searched one by one. With an approximate kind the pool is as good as the
        index's own answer for c.
    threads: FAISS OpenMP threads (0: leave FAISS's default).
    seed: seeds k-means training and the random parts of re-sampling.
    """

    kind: str = "auto"
    auto_flat_max: int = 200_000
    hnsw_m: int = 32
    hnsw_ef_construction: int = 64
    hnsw_ef_search: int = 128
    ivf_nlist: int = 0
    ivf_nprobe: int = 16
    ivf_train_max: int = 200_000
    pool_factor: float = 4.0
    pool_min: int = 128
    threads: int = 0
    seed: int = 0

    def __post_init__(self) -> None:
        if self.kind not in KINDS:
            raise AocError(f"unknown index kind {self.kind!r}; use one of {', '.join(KINDS)}")

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

    @classmethod
    def from_dict(cls, data: dict, strict: bool = True) -> "IndexConfig":
        """The config of ``data``'s settings. ``strict``: a key that is no setting (a typo such
        as ``kidn``) is an AocError; False (a saved index's config) ignores it."""
        names = {f.name for f in fields(cls)}
        unknown = sorted(set(data) - names)
        if strict and unknown:
            raise AocError(f"unknown index setting {unknown[0]!r}: the settings are "
                           f"{', '.join(sorted(names))}")
        return cls(**{key: value for key, value in data.items() if key in names})
