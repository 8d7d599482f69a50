"""The corpus index: a corpus's beliefs under a belief model and the index over them, between
:mod:`aoc_cli.decompose` (which it calls) and :mod:`aoc_cli.control` (which searches it).

>>> from aoc_cli.corpus_index import build_index, load_index
"""

from aoc_cli.corpus_index.build import (
    TYPICAL_SAMPLE,
    build_index,
    load_index,
    neighbours,
    typical_residual,
)
from aoc_cli.corpus_index.index import CorpusIndex, TypicalResidual
from aoc_cli.decompose.k_rule import SMALL_MAX_ROWS

__all__ = [
    "SMALL_MAX_ROWS",
    "TYPICAL_SAMPLE",
    "CorpusIndex",
    "TypicalResidual",
    "build_index",
    "load_index",
    "neighbours",
    "typical_residual",
]
