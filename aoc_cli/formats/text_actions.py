"""Treatments logged as text (``oxygen``, ``none``): discrete actions whose labels are kept.

A clinical log records what was done in words. An action column of a CSV whose cells are all
text (none parses as a number) is read as a discrete action: one action per distinct label,
numbered in the labels' sorted order, and the labels kept in the action space's ``names`` (one
label an action, where built-in tasks keep theirs, e.g. icu-sepsis's ``fluids=2,vaso=0``), so
``explain`` and ``evaluate`` show them and ``aoc export`` writes them back. Several action
columns of which one holds text make one discrete action per distinct combination, labelled
``col=value,col=value``. A column mixing numbers and text is an error naming the first text
cell (most likely a typo in a numeric column), as is an empty cell (a step with no action).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from aoc_cli.errors import AocError
from aoc_cli.formats.table import is_numeric, text, text_cells
from aoc_cli.store import discrete_space


def _at(row_label, row: int) -> str:
    return f" ({row_label(row)})" if row_label is not None else ""


def text_actions(path: Path | str, cols: dict, names: list[str], order: np.ndarray,
                 row_label=None) -> tuple[np.ndarray, dict] | None:
    """The discrete actions (N,) int64 and their labelled space when one of the action columns
    ``names`` (Arrow arrays) holds text, else None (the numeric reading applies). ``order``:
    the file row of each corpus row; ``row_label(i)``: text naming file row i's episode."""
    if all(is_numeric(cols[c]) for c in names):
        return None
    parts = []
    for c in names:
        cells = text(cols[c])
        empty = np.flatnonzero(cells == "")
        if empty.size:
            row = int(empty[0])
            raise AocError(f"{path}: column {c!r}, data row {row + 1}{_at(row_label, row)} is "
                           "empty: every step needs its action (a treatment given or not, "
                           "e.g. 'none')")
        numbers = text_cells(cells)
        if numbers.any() and not numbers.all():
            row = int(np.flatnonzero(~numbers)[0])
            raise AocError(f"{path}: column {c!r} mixes numbers and text (data row {row + 1}"
                           f"{_at(row_label, row)} holds {str(cells[row])!r}): an action "
                           "column holds numbers or labels, not both")
        parts.append(cells[order])
    labels_of_rows = parts[0] if len(parts) == 1 else np.array(
        [",".join(f"{c}={v}" for c, v in zip(names, row)) for row in zip(*parts)])
    labels, codes = np.unique(labels_of_rows, return_inverse=True)
    return codes.astype(np.int64), discrete_space(len(labels), [str(x) for x in labels])
