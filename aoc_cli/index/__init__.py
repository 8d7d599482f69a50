"""The index room: finding a query's nearest corpus rows, in two floors.

* :mod:`aoc_cli.index.search` (below :mod:`aoc_cli.decompose`): the search over an (N, d_b)
  array of beliefs (flat, HNSW, IVF, the exact search cell by cell, the candidates of every
  action, the batch search). It knows only arrays: importing it imports neither torch nor
  anything above it.
* :mod:`aoc_cli.index.corpus` and :mod:`aoc_cli.index.build` (above :mod:`aoc_cli.belief`):
  the corpus index, a corpus's beliefs under a belief model and the search over them
  (:class:`CorpusIndex`), built and loaded from a model (:func:`build_index`,
  :func:`load_index`); it calls :mod:`aoc_cli.decompose`, and :mod:`aoc_cli.control` searches
  it.

Names are imported lazily (PEP 562), so that importing the search floor loads nothing of the
corpus index.

>>> from aoc_cli.index import build_index, load_index
"""

from __future__ import annotations

from aoc_cli.lazy import exports

_WHERE = {
    "BeliefIndex": "search.belief_index",
    "CorpusIndex": "corpus",
    "IndexConfig": "search.config",
    "PerAction": "search.strata",
    "Selection": "search.belief_index",
    "TYPICAL_SAMPLE": "build",
    "TypicalResidual": "corpus",
    "build_index": "build",
    "load_index": "build",
    "model_k": "build",
    "typical_residual": "build",
}

__all__ = sorted(_WHERE)


__getattr__, __dir__ = exports(__name__, _WHERE)
