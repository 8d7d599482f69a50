"""Nearest-neighbour index over corpus beliefs (the index stage of the flow).

`BeliefIndex.build(beliefs, IndexConfig(kind=...))` indexes an (N, d) float32 belief array with
FAISS (exact "flat", approximate "hnsw" or "ivf", or "auto" by size); `search(queries, k,
selection)` returns the k nearest corpus rows, optionally restricted to a row mask or id list
(FAISS ID selectors, no rebuild); `resample` / `subsample` build derived indexes whose positions
map back to corpus rows (`row_of`); `save` / `load` persist atomically.
"""

from aoc_cli.index.belief_index import BeliefIndex, Selection
from aoc_cli.index.config import IndexConfig
from aoc_cli.index.strata import PerAction

__all__ = ["BeliefIndex", "IndexConfig", "PerAction", "Selection"]
