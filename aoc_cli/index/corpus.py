"""A built corpus index: a corpus's beliefs (N, d_b), their row values and the FAISS index
over them, with what it was built from (:class:`CorpusIndex`), and the corpus's typical
residual (:class:`TypicalResidual`). Built and loaded by :mod:`aoc_cli.index.build`."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np

from aoc_cli.decompose import decompose, default_k
from aoc_cli.index.search import BeliefIndex
from aoc_cli.index.search.strata import NEAREST, candidate_search

if TYPE_CHECKING:
    from aoc_cli.belief.artefact import BeliefModel


@dataclass(frozen=True)
class TypicalResidual:
    """The corpus's typical residual: quantiles of the residuals of ``sample`` held-out corpus
    rows decomposed against the other rows (``index.json`` ``typical_residual``). Each is None
    for an index that recorded none (fewer than 3 rows)."""

    p50: float | None = None
    p90: float | None = None
    p99: float | None = None
    sample: int = 0

    @classmethod
    def from_meta(cls, meta: dict) -> "TypicalResidual":
        """From an index's metadata (``index.json``)."""
        rec = meta.get("typical_residual") or {}
        return cls(*(None if rec.get(q) is None else float(rec[q]) for q in ("p50", "p90", "p99")),
                   sample=int(rec.get("sample") or 0))


@dataclass
class CorpusIndex:
    """A built index: model, beliefs of every corpus row (N, d_b), row values (N,), the FAISS
    index (possibly derived: re-sampled or sub-sampled rows) and what it was built from."""

    index_id: str
    model: BeliefModel
    beliefs: np.ndarray
    values: np.ndarray | None
    index: BeliefIndex
    meta: dict
    strata: np.ndarray | None = None
    _search: object = field(default=None, init=False, repr=False)

    @property
    def candidates(self) -> str:
        """Step 1's candidates (``index.json`` ``candidates``): "nearest", the k nearest rows;
        "per_action", the k / n nearest rows of each of the n actions
        (:mod:`aoc_cli.index.search.strata`). An index that recorded none: "nearest"."""
        return self.meta.get("candidates") or NEAREST

    @property
    def search(self):
        """The search step 1 uses: the index, or the index per action."""
        if self._search is None:
            self._search = candidate_search(self.index, self.candidates, self.strata)
        return self._search

    @property
    def typical(self) -> TypicalResidual:
        """The corpus's typical residual (p50, p90, p99), as the index recorded it."""
        return TypicalResidual.from_meta(self.meta)

    @property
    def typical_residual(self) -> float | None:
        """The typical (p50) residual: what a decision's residual is compared with."""
        return self.typical.p50

    @property
    def rows(self) -> np.ndarray:
        """(M,) the corpus row of every index entry (repeats when re-sampled)."""
        return self.index.row_of

    def decompose(self, queries: np.ndarray, k: int | None = None,
                  selection: np.ndarray | None = None):
        """Decompose query beliefs (Q, d_b) over the corpus; ``rows`` are corpus rows.

        ``selection`` is an (N,) bool mask over corpus rows, applied at query time.
        """
        queries = np.asarray(queries, dtype=np.float32)  # the beliefs' precision; checked there
        return decompose(self.beliefs, queries, k=self.k if k is None else k,
                         values=self.values, index=self.search, selection=selection)

    @property
    def k(self) -> int:
        """Neighbours per query when none is given: the one the index was built with
        (``index.json`` ``k``, :func:`aoc_cli.index.build.model_k`); the paper's for an index without it."""
        return int(self.meta.get("k") or default_k(self.beliefs.shape[1]))
