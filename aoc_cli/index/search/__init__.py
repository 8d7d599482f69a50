"""The search floor of the index room: nearest rows over corpus beliefs, arrays only.

`BeliefIndex.build(beliefs, IndexConfig(kind=...))` indexes an (N, d) float32 belief array with
FAISS (exact "flat", approximate "hnsw" or "ivf", or "auto" by size); `search(queries, k,
selection)` returns the k nearest corpus rows, optionally restricted to a row mask or id list
(FAISS ID selectors, no rebuild); `resample` / `subsample` build derived indexes whose positions
map back to corpus rows (`row_of`); `save` / `load` persist atomically. `PerAction`
(strata.py) takes the candidates of every action; `BatchSearch` (batch.py) searches many
scattered queries at once over an IVF structure built for the run.

Names are imported lazily (PEP 562), so that reading the index's settings
(:mod:`aoc_cli.index.search.config`, as ``aoc index --help`` does) does not import FAISS.
"""

from __future__ import annotations

from aoc_cli.lazy import exports

_WHERE = {"BatchSearch": "batch", "BeliefIndex": "belief_index", "IndexConfig": "config",
          "PerAction": "strata", "Selection": "belief_index"}

__all__ = sorted(_WHERE)


__getattr__, __dir__ = exports(__name__, _WHERE)
