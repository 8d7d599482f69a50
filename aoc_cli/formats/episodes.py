"""The rows of a table ordered into episodes: by episode id (numerically when every id is a
number, else as text; ids that are the same number, ``7`` and ``007``, are one episode), then
by time (numbers or ISO dates), stable; two rows of one episode at one time are an error
naming them. A file already in that order is neither sorted nor gathered (``in_order``). The
ids are hashed by Arrow, so only the distinct ids become Python text."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pyarrow as pa
import pyarrow.compute as pc

from aoc_cli.errors import AocError, warn
from aoc_cli.formats.csv_stream import arrow_values
from aoc_cli.formats.table import Table, is_numeric, is_text_type, numeric, text


def sort_key(col: pa.ChunkedArray, name: str, where, dates: bool) -> np.ndarray:
    """Numbers if every value is a number, else (time only) dates, else (ids) the text."""
    if isinstance(col, np.ndarray):  # a streamed column of numbers
        return col
    if pa.types.is_timestamp(col.type) or pa.types.is_date(col.type):
        return col.cast(pa.timestamp("ns")).cast(pa.int64()).to_numpy(zero_copy_only=False)
    if is_numeric(col):
        return numeric(col, name, where)
    values = text(col)
    if dates:
        try:
            return np.array(values, dtype="datetime64[ns]").astype(np.int64)
        except ValueError:
            raise AocError(f"{where}: time column {name!r} holds neither numbers nor ISO dates "
                           f"(e.g. {str(values[0])!r})") from None
    return values



@dataclass
class Episodes:
    """Rows ordered by (id, time): ``order`` (N,) file row of each corpus row (``in_order``:
    the file already is), ``starts`` (E + 1,), the id of each episode as text and as its sort
    key; ``row_codes`` (N,) index each file row's id text in ``texts`` (messages name a row's
    stay by it)."""

    order: np.ndarray
    starts: np.ndarray
    ids: list[str]
    keys: np.ndarray
    row_codes: np.ndarray
    texts: np.ndarray
    id_name: str | None
    in_order: bool = False

    def take(self, x: np.ndarray) -> np.ndarray:
        """A column's file rows in corpus order (itself when the file is in order)."""
        return x if self.in_order else x[self.order]

    def row_id(self, i: int) -> str:
        """File row ``i``'s id text."""
        return str(self.texts[self.row_codes[i]])

    def row_label(self, i: int) -> str:
        """Text naming file row ``i``'s episode: ``icustayid 1007``."""
        return f"{self.id_name} {self.row_id(i)}" if self.id_name else "the only episode"

    def corpus_row_label(self, r: int) -> str:
        """``data row 12 (icustayid 1007)`` for corpus row ``r``."""
        i = int(self.order[r])
        return f"data row {i + 1} ({self.row_label(i)})"


def _ids(col: pa.ChunkedArray, name: str, where) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """An id column -> (codes (N,) int64 indexing ``texts``, texts (U,) the distinct ids,
    stripped, empty cells ``''``; keys (U,) their sort keys: numbers when every id is one,
    else the text). Hashed by Arrow, so only the U distinct ids become Python text."""
    if is_text_type(col.type):  # the distinct cells found first, then only they trimmed
        distinct = pc.unique(col)
        found = pc.index_in(col, value_set=distinct)  # every cell is one of them
        parts = [arrow_values(c) for c in found.chunks]
        if any(valid is not None for _v, valid in parts):
            raise AssertionError("an id cell not among the column's distinct cells")
        codes = np.concatenate([v for v, _valid in parts] or [np.zeros(0, np.int32)])
        trimmed = pc.utf8_trim_whitespace(distinct)
        texts = np.array(["" if t is None else t for t in trimmed.to_pylist()], dtype=str)
        return codes.astype(np.int64), texts, _id_keys(trimmed, texts)
        # " 7" and "7": two texts of one key, one episode
    values = text(col)
    texts, codes = np.unique(values, return_inverse=True)
    keys = sort_key(col, name, where, dates=False)
    first = np.zeros(len(texts), np.int64)
    first[codes[::-1]] = np.arange(len(codes))[::-1]
    return codes.astype(np.int64), texts, np.asarray(keys)[first]


def _id_keys(trimmed: pa.Array, texts: np.ndarray) -> np.ndarray:
    """The sort keys of the distinct ids: numbers (NaN for the empty id) when every other id
    reads as one, else their text; Arrow's casts, no Python value made an Arrow one (that
    would import pandas, ~0.5 s)."""
    present = pc.filter(trimmed, pc.cast(pc.utf8_length(trimmed), pa.bool_()))  # not empty
    try:
        numbers = pc.cast(present, pa.float64())
    except pa.ArrowInvalid:
        return texts
    keys = np.full(len(texts), np.nan)
    values, _valid = arrow_values(numbers)  # no nulls: the empty ids were filtered out
    keys[texts != ""] = values
    return keys


def order_episodes(table: Table, id_col: str | None, time_col: str | None) -> Episodes:
    """Order the rows by episode id and time (stable); warn about empty ids; two rows of one
    episode at one time are an AocError naming them."""
    n, cols, where = table.n, table.cols, table.where
    if id_col:
        codes, texts, keys = _ids(cols[id_col], id_col, where)
    else:
        codes, texts, keys = np.zeros(n, np.int64), np.array(["0"]), np.zeros(1)
    if id_col and "" in texts:
        rows = np.flatnonzero(codes == int(np.flatnonzero(texts == "")[0]))
        warn(f"{where}: {len(rows)} rows have an empty {id_col!r} cell (first: data row "
             f"{int(rows[0]) + 1}); they form one episode with the id ''")
    uniq_keys, rank = np.unique(keys, return_inverse=True)  # ids of one number: one episode
    id_codes = rank.reshape(-1)[codes]
    time_key = np.asarray(sort_key(cols[time_col], time_col, where, dates=True)) \
        if time_col else np.arange(n)
    d_id, d_time = np.diff(id_codes), np.diff(time_key)
    in_order = bool(((d_id > 0) | ((d_id == 0) & (d_time > 0))).all())  # no sort, no repeat
    order = np.arange(n) if in_order else np.lexsort((time_key, id_codes))
    if not in_order:
        id_codes = id_codes[order]
    if time_col and not in_order:
        same = (np.diff(id_codes) == 0) & (np.diff(time_key[order]) == 0)
        if same.any():
            k = int(np.flatnonzero(same)[0])
            a, b = sorted((int(order[k]), int(order[k + 1])))
            stay = f"{id_col} {texts[codes[a]]}, " if id_col else ""
            raise AocError(f"{where}: data rows {a + 1} and {b + 1} are both at ({stay}"
                           f"{time_col} {text(cols[time_col])[a]}) ({int(same.sum())} "
                           "such repeats): one row per stay and time; remove the duplicates")
    bounds = np.flatnonzero(np.diff(id_codes)) + 1
    starts = np.concatenate([[0], bounds, [n]]).astype(np.int64)
    first = order[starts[:-1]]
    return Episodes(order, starts, [str(t) for t in texts[codes[first]]],
                    uniq_keys[id_codes[starts[:-1]]], codes, texts, id_col, in_order)
