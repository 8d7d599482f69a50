"""Nearest-neighbour index over corpus beliefs (the index stage of the flow).

`BeliefIndex.build(beliefs, IndexConfig(kind=...))` indexes an (N, d) float32 belief array with
FAISS (exact "flat", approximate "hnsw" or "ivf", or "auto" by size); `search(queries, k,
selection)` returns the k nearest corpus rows, optionally restricted to a row mask or id list
(FAISS ID selectors, no rebuild); `resample` / `subsample` build derived indexes whose positions
map back to corpus rows (`row_of`); `save` / `load` persist atomically.

Names are imported lazily (PEP 562), so that reading the index's settings
(:mod:`aoc_cli.neighbours.config`, as ``aoc index --help`` does) does not import FAISS.
"""

from __future__ import annotations

from aoc_cli.lazy import exports

_WHERE = {"BeliefIndex": "belief_index", "IndexConfig": "config", "PerAction": "strata",
          "Selection": "belief_index"}

__all__ = sorted(_WHERE)


__getattr__, __dir__ = exports(__name__, _WHERE)
