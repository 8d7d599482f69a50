"""An (N, k) observation matrix kept as its k columns until it is written.

A table's reader converts and fills one column at a time (:mod:`aoc_cli.formats.csv`); the
row-major (N, k) matrix the store holds is only ever made block by block, as the writer puts it
into ``corpus.h5`` and hashes it (:mod:`aoc_cli.store.writer`). So a cohort of 229k rows x 84
features never holds its 154 MB of float64 rows beside the 81 MB of columns they come from
(peak memory <= 3x the CSV's size, benchmarks/perf/ingest.py). The ``COL?measured`` 0/1
features stay bool columns (one byte a cell) until a block casts them.

Anything that needs the whole matrix gets it from ``np.asarray`` (``--append``, a selection
of episodes); the values are the same either way.
"""

from __future__ import annotations

from typing import Iterator

import numpy as np

#: Rows per block: 84 float64 columns of 2,048 rows (1.4 MB) stay in the CPU's cache while
#: they are gathered, written and hashed.
BLOCK_ROWS = 2048


class ColumnStack:
    """(N, k) rows of ``dtype`` (float64, or bool for a mask) made from k columns, each (N,)
    float64 or bool; ``negate[j]``: column j is the negation of its bool array (a
    ``COL?measured`` feature is ``~empty``: the one array serves the imputed mask and the
    feature)."""

    def __init__(self, columns: list[np.ndarray], dtype=np.float64,
                 negate: list[bool] | None = None):
        if not columns:
            raise ValueError("a ColumnStack needs at least one column")
        n = len(columns[0])
        if any(c.ndim != 1 or len(c) != n for c in columns):
            raise ValueError("the columns of a ColumnStack must be (N,) arrays of one length")
        self.columns = list(columns)
        self.dtype = np.dtype(dtype)
        self.negate = list(negate) if negate is not None else [False] * len(columns)
        self._finite = False  # all_finite() once true
        if any(neg and c.dtype != bool for neg, c in zip(self.negate, self.columns)):
            raise ValueError("only bool columns of a ColumnStack can be negated")

    @property
    def shape(self) -> tuple[int, int]:
        return (len(self.columns[0]), len(self.columns))

    ndim = 2

    def __len__(self) -> int:
        return self.shape[0]

    def rows(self, start: int, stop: int, out: np.ndarray | None = None) -> np.ndarray:
        """Rows [start, stop) as a C-ordered (stop - start, k) array (into ``out``, when
        given, of at least that many rows)."""
        n = stop - start
        block = np.empty((n, len(self.columns)), self.dtype) if out is None else out[:n]
        for j, (col, neg) in enumerate(zip(self.columns, self.negate)):
            block[:, j] = ~col[start:stop] if neg else col[start:stop]
        return block

    def blocks(self, size: int = BLOCK_ROWS) -> Iterator[tuple[int, np.ndarray]]:
        """(first row, rows) of consecutive blocks of ``size`` rows; one buffer reused: a
        block is valid until the next one is made."""
        buf = np.empty((min(size, len(self)), len(self.columns)), self.dtype)
        for a in range(0, len(self), size):
            yield a, self.rows(a, min(a + size, len(self)), buf)

    def __array__(self, dtype=None, copy=None) -> np.ndarray:
        out = self.rows(0, len(self))
        return out if dtype is None else out.astype(dtype, copy=False)

    def column(self, j: int) -> np.ndarray:
        """Column j (N,) as the rows hold it."""
        col = ~self.columns[j] if self.negate[j] else self.columns[j]
        return col.astype(self.dtype, copy=False)

    def column_sums(self) -> np.ndarray:
        """(k,) the sum of each column (a mask: its true cells per column)."""
        return np.array([self.column(j).sum() for j in range(len(self.columns))])

    def any(self) -> bool:
        return any(bool(self.column(j).any()) for j in range(len(self.columns)))

    def finite_rows(self) -> np.ndarray:
        """(N,) bool: rows whose every value is finite (column by column, no (N, k) copy)."""
        ok = np.ones(len(self), bool)
        for col in self.columns:
            if col.dtype.kind == "f":
                ok &= np.isfinite(col)
        return ok

    def all_finite(self) -> bool:
        """Whether every value is finite (a column's sum first: NaN and inf propagate). Found
        once (reading, validating and writing each ask; the columns are not changed once
        stacked)."""
        if not self._finite:
            with np.errstate(over="ignore", invalid="ignore"):
                self._finite = all(col.dtype.kind != "f" or bool(np.isfinite(col.sum()))
                                   or bool(np.isfinite(col).all()) for col in self.columns)
        return self._finite
