"""Candidates of every action: the nearest corpus rows of each stratum (ABC's imitation step 1).

Step 1 of the decomposition takes the k nearest corpus beliefs of a query. In imitation mode
with a rare action, the k nearest rows of a query in a region where that action is seldom
logged often hold none of it: the minimal corpus subset then weighs the rare action 0 and
the decision's scores tie at exactly 0 or 1 (docs/design.md, "Candidates of every action").
:class:`PerAction` asks a search for the nearest rows *of each action* instead: with S
actions present and k neighbours asked for, the ``k // S`` nearest rows of every action,
joined and ordered by distance. Steps 2-4 are unchanged: the query is projected on the hull
of the joined candidates, and its minimal corpus subset (at most d_b + 1 rows) places it
between the actions' nearest rows.
"""

from __future__ import annotations

import numpy as np

from aoc_cli.errors import AocError, call

#: The ``candidates`` an index records (``index.json``): the k nearest rows, or the nearest
#: rows of each action.
NEAREST, PER_ACTION = "nearest", "per_action"


class PerAction:
    """``search`` (a BeliefIndex, or anything with its ``search(queries, k, selection)``,
    ``n_rows`` and ``dim``) seen per stratum. ``strata`` (N,) int: each corpus row's stratum
    (its discrete action). ``search(Y, k, selection)`` returns distances and rows (Q, S * per),
    per = max(1, k // S) over the S strata present, the nearest ``per`` of each stratum
    (within ``selection``), ascending by distance, -1 / inf padded where a stratum has fewer
    rows.

    Each stratum is searched in ``search`` restricted to its rows (a row mask, exact for a
    flat index's batches), or, with ``split`` (a function: corpus rows (n,) -> a search over
    those rows alone, numbered 0..n-1), in a search of its own: an approximate structure
    (IVF) restricted by a mask visits the lists near the query, where a far stratum has few
    rows, and so returns fewer than asked; one built per stratum does not."""

    def __init__(self, search, strata: np.ndarray, split=None):
        strata = np.asarray(strata, dtype=np.int64)
        if strata.shape != (search.n_rows,):
            raise AocError(f"internal: {strata.shape} strata for {search.n_rows} corpus rows")
        self.base, self.n_rows, self.dim = search, search.n_rows, search.dim
        self.masks = [strata == s for s in np.unique(strata)]
        self.rows = [np.flatnonzero(m) for m in self.masks]
        self.subs = None if split is None else [split(r) for r in self.rows]
        select = getattr(search, "select", None)  # a BeliefIndex prepares its masks once
        self._prepared = [select(m) for m in self.masks] if select is not None and \
            split is None else self.masks

    def wrapped(self, wrap) -> "PerAction":
        """The same strata over ``wrap(search, rows)`` of each search (rows None: the base
        over every row; else a stratum's own search and its corpus rows)."""
        out = object.__new__(PerAction)
        out.__dict__.update(self.__dict__)
        if self.subs is None:
            out.base = wrap(self.base, None)
        else:
            out.subs = [wrap(sub, rows) for sub, rows in zip(self.subs, self.rows)]
        return out

    def per(self, k: int) -> int:
        """Rows of each stratum for k neighbours."""
        return max(1, int(k) // len(self.masks))

    def search(self, queries, k: int, selection=None) -> tuple[np.ndarray, np.ndarray]:
        per = self.per(k)
        sel = None
        if selection is not None:
            sel = np.asarray(selection)
            if sel.dtype != bool:
                mask = np.zeros(self.n_rows, bool)
                mask[sel.astype(np.int64)] = True
                sel = mask
        ds, rs = [], []
        for i, rows in enumerate(self.rows):
            if self.subs is not None:
                part = None if sel is None else sel[rows]
                count = len(rows) if part is None else int(part.sum())
                if count:
                    d, r = self.subs[i].search(queries, min(per, count), part)
                    r = np.where(r >= 0, rows[np.maximum(r, 0)], -1)
            else:
                part = self._prepared[i] if sel is None else self.masks[i] & sel
                count = len(rows) if sel is None else int(part.sum())
                if count:
                    d, r = self.base.search(queries, min(per, count), part)
                    # an approximate index visits the lists / graph near the query, where a
                    # far stratum may have fewer rows than asked: those queries exactly
                    short = (r < 0).any(1)
                    if short.any() and hasattr(self.base, "search_exact"):
                        d[short], r[short] = self.base.search_exact(
                            np.asarray(queries)[short], min(per, count), part)
            if count:
                ds.append(d)
                rs.append(r)
        if not ds:
            raise AocError("the selection leaves no corpus rows in the index; select at least one row")
        d, r = np.concatenate(ds, axis=1), np.concatenate(rs, axis=1)
        order = np.argsort(d, axis=1, kind="stable")
        return np.take_along_axis(d, order, axis=1), np.take_along_axis(r, order, axis=1)

    def row_beliefs(self, rows: np.ndarray) -> np.ndarray | None:
        """The base search's float32 beliefs of ``rows``, when it keeps them (BeliefIndex)."""
        gather = getattr(self.base, "row_beliefs", None)
        return None if gather is None else gather(rows)

    def describe(self, inner: str = "the index") -> str:
        """What step 1 searches, ``inner`` the search over every row."""
        if self.subs is not None:
            inner = f"{inner}; a search of each"
        return f"the nearest rows of each of {len(self.masks)} actions ({inner})"


def candidate_search(search, candidates: str | None, strata: np.ndarray | None, split=None):
    """The search step 1 uses: ``search`` itself for the k nearest rows (``candidates``
    "nearest" or None, an index that recorded none), :class:`PerAction` over ``strata`` for
    "per_action" (``split``: see there)."""
    if candidates in (None, NEAREST):
        return search
    if candidates == PER_ACTION:
        if strata is None:
            raise AocError("internal: per-action candidates need the rows' actions")
        return PerAction(search, strata, split)
    raise AocError(f"unknown candidates {candidates!r} in the index: rebuild it with "
                   f"`{call('build_index')}`")
