"""Delimited text tables (CSV, ``.tsv``, gzip-compressed ``.gz``) read into columns of text,
and text columns read as numbers: what the CSV log reader (:mod:`aoc_cli.formats.csv`) and
its static covariates (:mod:`aoc_cli.formats.static`) build on.
"""

from __future__ import annotations

import csv
import gzip
import io
import zlib
from pathlib import Path

import numpy as np

from aoc_cli.errors import AocError

#: Rows between progress reports while a large file is parsed.
CHUNK_LINES = 50_000


def read_table(path: Path, progress=None) -> tuple[list[str], dict[str, np.ndarray]]:
    """A CSV (``.tsv``: tab-separated; ``.gz``: gzip) -> (header, column name -> (N,) str).

    Quoted fields may span lines (free-text notes exported from a spreadsheet); blank lines
    are skipped.
    """
    text = _read_text(path)
    delimiter = "\t" if ".tsv" in path.suffixes else ","
    try:
        return _parse(path, text, delimiter, progress)
    except csv.Error as err:
        raise AocError(f"cannot read {path} as CSV ({err}): fix the file") from None


def _read_text(path: Path) -> str:
    """The text of a file (gunzipped for ``.gz``); unreadable or empty is one AocError."""
    opener = gzip.open if path.suffix == ".gz" else open
    try:
        with opener(path, "rt", encoding="utf-8-sig", newline="") as fh:
            text = fh.read()
    except (OSError, UnicodeDecodeError, EOFError, zlib.error) as err:
        raise AocError(f"cannot read {path} as UTF-8 text ({type(err).__name__}: {err}); "
                       "a .gz file must be gzip-compressed CSV") from None
    if not text.strip():
        raise AocError(f"{path} is empty: expected a header line and one row per step")
    return text


def _parse(path: Path, text: str, delimiter: str, progress):
    reader = csv.reader(io.StringIO(text), delimiter=delimiter)
    header = [h.strip() for h in next(reader)]
    if "" in header:
        raise AocError(f"{path}: header column {header.index('') + 1} has no name: name it")
    if len(set(header)) != len(header):
        dup = sorted({h for h in header if header.count(h) > 1})
        raise AocError(f"{path} repeats column names {dup}: rename them")
    rows: list[list[str]] = []
    # progress in physical lines (a quoted field may span several); no bar for a small file
    lines, label = text.count("\n") + 1, f"reading {path.name}"
    if lines <= CHUNK_LINES:
        progress = None
    for r in reader:
        if not r or (len(r) == 1 and not r[0].strip()):
            continue  # a blank line
        if len(r) != len(header):
            raise AocError(f"{path}: data row {len(rows) + 1} (line {reader.line_num}) has "
                           f"{len(r)} fields, the header has {len(header)}: fix the file")
        rows.append(r)
        if progress is not None and len(rows) % CHUNK_LINES == 0:
            progress(min(reader.line_num, lines), lines, label)
    if progress is not None:
        progress(lines, lines, label)
    if not rows:
        return header, {h: np.array([], dtype=str) for h in header}
    cols = [np.array(c, dtype=str) for c in zip(*rows)]
    return header, dict(zip(header, cols))


def numeric(values: np.ndarray, name: str, path: Path) -> np.ndarray:
    """(N,) strings -> float64; empty cells are NaN; anything else that is not a number is
    an AocError naming the row."""
    stripped = np.char.strip(values)
    stripped = np.where(stripped == "", "nan", stripped)
    try:
        return stripped.astype(np.float64)
    except ValueError:
        for i, v in enumerate(stripped):
            try:
                float(v)
            except ValueError:
                raise AocError(f"{path}: column {name!r}, data row {i + 1} holds "
                               f"{str(v)!r}, not a number") from None
    raise AssertionError("unreachable")


def is_numeric(values: np.ndarray) -> bool:
    """Whether every cell of (N,) strings is a number or empty."""
    try:
        np.where(np.char.strip(values) == "", "nan", np.char.strip(values)).astype(np.float64)
        return True
    except ValueError:
        return False
