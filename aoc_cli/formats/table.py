"""Tables read on pyarrow: CSV (``.tsv``: tab-separated; ``.gz``: gzip-compressed), Parquet,
and in-memory Arrow tables or pandas / polars DataFrames, as columns of Arrow arrays; and
those columns as numbers or text. What the tabular log reader (:mod:`aoc_cli.formats.csv`)
and its static covariates (:mod:`aoc_cli.formats.static`) build on.

pyarrow's readers are typed and null-aware: an empty cell of a number column is a null (NaN
once converted), a column holding text stays text. A CSV is streamed block by block first
(:mod:`aoc_cli.formats.csv_stream`: the types inferred from the first block, its number
columns written straight into float64 numpy arrays, the others kept as Arrow chunks). When
streaming fails (a later block holds what the first one's types cannot, a quoted line
break) the whole file is read at once, allowing quoted line breaks (a spreadsheet's free-text
notes), and only when that fails too is the bad row found, with Python's ``csv`` module, to
name it. A column is then either such a numpy array or an Arrow chunked array (Parquet,
frames, the whole-file read, text); :func:`numeric`, :func:`text`, :func:`has_gaps` and
:func:`is_numeric` take both.
"""

from __future__ import annotations

import csv
import gzip
import zlib
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.compute as pc
import pyarrow.csv as pacsv
import pyarrow.parquet as pq

from aoc_cli.errors import AocError
from aoc_cli.formats.csv_stream import BLOCK_BYTES, streamed

#: A Parquet file starts (and ends) with these bytes.
PARQUET_MAGIC = b"PAR1"


@dataclass
class Table:
    """Columns of a table: ``header`` in file order, ``cols[name]`` an Arrow array of ``n``
    entries or (a streamed CSV's numbers) an (n,) float64 array; ``where``: the file (or
    ``the frame``) that messages name."""

    where: str
    header: list[str]
    cols: dict[str, pa.ChunkedArray | np.ndarray]
    n: int


def read_table(path: Path, progress=None, text_columns=()) -> Table:
    """A CSV, TSV, gzip-compressed CSV or Parquet file -> its :class:`Table`.

    ``text_columns``: columns read as text whatever they hold (episode ids such as ``007``,
    tag labels). ``progress(done, total, label)`` is told the bytes read, at the start and
    the end (pyarrow reads the whole file in one call, on several threads).
    """
    path = Path(path)
    size = path.stat().st_size if path.exists() else 0
    label = f"reading {path.name}"
    if progress is not None:
        progress(0, size, label)
    if is_parquet(path):
        table = _read_parquet(path)
    else:
        table = _read_csv(path, text_columns)
    if progress is not None:
        progress(size, size, label)
    return _checked(table, str(path), text_columns)


def from_frame(frame, text_columns=()) -> Table:
    """An Arrow table, a pandas or polars DataFrame (anything with ``__arrow_c_stream__`` or
    ``to_arrow``) -> its :class:`Table`."""
    try:
        if isinstance(frame, pa.RecordBatch):
            frame = pa.Table.from_batches([frame])
        if not isinstance(frame, pa.Table):
            if hasattr(frame, "to_arrow"):  # polars
                frame = frame.to_arrow()
            elif type(frame).__module__.startswith("pandas"):
                frame = pa.Table.from_pandas(frame, preserve_index=False)
            else:
                frame = pa.table(frame)
    except (pa.ArrowException, TypeError, ValueError) as err:
        raise AocError(f"cannot read the frame as a table ({type(err).__name__}: "
                       f"{str(err).splitlines()[0][:160]}): pass an Arrow table or a pandas "
                       "or polars DataFrame") from None
    return _checked(frame, "the frame", text_columns)


def is_parquet(path: Path) -> bool:
    """A ``.parquet`` name, or the Parquet magic at the start of the file."""
    if Path(path).suffix.lower() in (".parquet", ".pq"):
        return True
    try:
        with open(path, "rb") as fh:
            return fh.read(4) == PARQUET_MAGIC
    except OSError:
        return False


def _read_parquet(path: Path) -> pa.Table:
    try:
        return pq.read_table(path)
    except (pa.ArrowException, OSError) as err:
        raise AocError(f"cannot read {path} as Parquet ({_first(err)}): re-write the "
                       "file") from None


def _read_csv(path: Path, text_columns) -> pa.Table | Table:
    """The streamed :class:`Table` (numeric columns already numpy), else, when streaming
    fails, the whole file as an Arrow table."""
    delimiter = "\t" if ".tsv" in [s.lower() for s in path.suffixes] else ","
    header = _header(path, delimiter)
    convert = pacsv.ConvertOptions(
        column_types={c: pa.string() for c in text_columns if c in header},
        strings_can_be_null=False, quoted_strings_can_be_null=False)
    for newlines in (False, True):  # streamed first; the whole file, quoted line breaks, next
        parse = pacsv.ParseOptions(delimiter=delimiter, newlines_in_values=newlines)
        try:
            if not newlines:
                header, cols, n = streamed(path, parse, convert)
                names = [str(h).strip() for h in header]
                _check_names(names, str(path))
                return Table(str(path), names, dict(zip(names, cols)), n)
            return pacsv.read_csv(path, read_options=pacsv.ReadOptions(
                block_size=BLOCK_BYTES), parse_options=parse, convert_options=convert)
        except pa.ArrowInvalid as err:
            failure = err
        except (OSError, pa.ArrowException) as err:
            raise AocError(f"cannot read {path} as CSV ({_first(err)}); a .gz file must be "
                           "gzip-compressed CSV") from None
    _name_bad_row(path, delimiter, len(header))
    raise AocError(f"cannot read {path} as CSV ({_first(failure)}): fix the file")


def _first(err: Exception) -> str:
    text = str(err).strip()
    return text.splitlines()[0][:200] if text else type(err).__name__


def _open_text(path: Path):
    opener = gzip.open if path.suffix.lower() == ".gz" else open
    return opener(path, "rt", encoding="utf-8-sig", newline="")


def _header(path: Path, delimiter: str) -> list[str]:
    """The header line's names; a file that is empty, not text or not gzip is an AocError,
    as is a header with an unnamed or repeated column."""
    try:
        with _open_text(path) as fh:
            first = next(csv.reader(fh, delimiter=delimiter), None)
    except (OSError, UnicodeDecodeError, EOFError, zlib.error, csv.Error) as err:
        raise AocError(f"cannot read {path} as UTF-8 text ({type(err).__name__}: {err}); "
                       "a .gz file must be gzip-compressed CSV") from None
    if not first or not any(h.strip() for h in first):
        raise AocError(f"{path} is empty: expected a header line and one row per step")
    header = [h.strip() for h in first]
    if "" in header:
        raise AocError(f"{path}: header column {header.index('') + 1} has no name: name it")
    if len(set(header)) != len(header):
        dup = sorted({h for h in header if header.count(h) > 1})
        raise AocError(f"{path} repeats column names {dup}: rename them")
    return header


def _name_bad_row(path: Path, delimiter: str, width: int) -> None:
    """The row pyarrow refused, found by Python's csv module: an AocError naming it."""
    with _open_text(path) as fh:
        reader = csv.reader(fh, delimiter=delimiter)
        next(reader, None)
        rows = 0
        try:
            for r in reader:
                if not r or (len(r) == 1 and not r[0].strip()):
                    continue  # a blank line
                rows += 1
                if len(r) != width:
                    raise AocError(f"{path}: data row {rows} (line {reader.line_num}) has "
                                   f"{len(r)} fields, the header has {width}: fix the file")
        except csv.Error as err:
            raise AocError(f"cannot read {path} as CSV ({err}): fix the file") from None


def _check_names(header: list[str], where: str) -> None:
    if "" in header:
        raise AocError(f"{where}: column {header.index('') + 1} has no name: name it")
    if len(set(header)) != len(header):
        dup = sorted({h for h in header if header.count(h) > 1})
        raise AocError(f"{where} repeats column names {dup}: rename them")


def _checked(table: pa.Table | Table, where: str, text_columns) -> Table:
    if isinstance(table, Table):  # streamed: names checked, text columns read as text
        return table
    header = [str(h).strip() for h in table.column_names]
    _check_names(header, where)
    cols = {}
    for h, col in zip(header, table.columns):
        if pa.types.is_dictionary(col.type):
            col = pa.chunked_array([c.dictionary_decode() for c in col.chunks],
                                   type=col.type.value_type)
        if h in text_columns and not is_text_type(col.type):
            col = pc.cast(col, pa.string())
        cols[h] = col
    return Table(where, header, cols, table.num_rows)


def is_text_type(t) -> bool:
    return pa.types.is_string(t) or pa.types.is_large_string(t)


def has_gaps(col: pa.ChunkedArray | np.ndarray) -> bool:
    """Whether a column has empty cells (nulls; NaN; empty text)."""
    if isinstance(col, np.ndarray):
        return bool(np.isnan(col).any())
    if col.null_count:
        return True
    if pa.types.is_floating(col.type):
        return bool(pc.any(pc.is_nan(col)).as_py())
    if is_text_type(col.type):
        return bool(pc.any(pc.equal(pc.utf8_trim_whitespace(col), "")).as_py())
    return False


def numeric(col: pa.ChunkedArray | np.ndarray, name: str, where, row_label=None) -> np.ndarray:
    """An Arrow column -> (N,) float64; empty and null cells are NaN; a cell that is not a
    number is an AocError naming its row (``row_label(i)``: text naming row i's episode). A
    column the streamed reader already made numbers is itself (not a copy)."""
    if isinstance(col, np.ndarray):
        return col
    t = col.type
    if pa.types.is_null(t):
        return np.full(len(col), np.nan)
    if pa.types.is_integer(t) or pa.types.is_floating(t) or pa.types.is_boolean(t) or \
            pa.types.is_decimal(t):
        if not pa.types.is_float64(t):
            col = pc.cast(col, pa.float64())
        return col.to_numpy()
    if not is_text_type(t):
        raise AocError(f"{where}: column {name!r} holds {t} values, not numbers")
    trimmed = _trimmed(col)
    try:
        return pc.cast(trimmed, pa.float64()).to_numpy()
    except pa.ArrowInvalid:
        i, cell = _first_text_cell(trimmed)
        at = f" ({row_label(i)})" if row_label is not None else ""
        raise AocError(f"{where}: column {name!r}, data row {i + 1}{at} holds {cell!r}, not "
                       "a number") from None


def _trimmed(col: pa.Array) -> pa.Array:
    """Text cells without surrounding spaces; empty cells null."""
    trimmed = pc.utf8_trim_whitespace(col)
    return pc.if_else(pc.equal(trimmed, ""), pa.scalar(None, trimmed.type), trimmed)


def _first_text_cell(trimmed: pa.Array) -> tuple[int, str]:
    """(row, cell) of the first non-empty cell of a text column that is not a number."""
    cells = trimmed.to_pylist()
    for i, v in enumerate(cells):
        if v is None:
            continue
        try:
            float(v)
        except ValueError:
            return i, v
    raise AssertionError("unreachable: the cast failed on some cell")


def text_cells(cells: np.ndarray | list) -> np.ndarray:
    """(N,) bool: which stripped text cells parse as numbers (empty cells do not)."""
    out = np.zeros(len(cells), dtype=bool)
    for i, v in enumerate(cells):
        try:
            float(v)
            out[i] = v != ""
        except ValueError:
            pass
    return out


def is_numeric(col: pa.Array | np.ndarray) -> bool:
    """Whether every cell of a column is a number or empty."""
    if isinstance(col, np.ndarray):
        return True
    t = col.type
    if pa.types.is_null(t) or pa.types.is_integer(t) or pa.types.is_floating(t) or \
            pa.types.is_boolean(t) or pa.types.is_decimal(t):
        return True
    if not is_text_type(t):
        return False
    try:
        pc.cast(_trimmed(col), pa.float64())
        return True
    except pa.ArrowInvalid:
        return False


def text(col: pa.Array | np.ndarray) -> np.ndarray:
    """An Arrow column -> (N,) str, stripped; empty and null cells ``''`` (a column of numbers
    as Arrow writes them: whole numbers without ``.0``; NaN empty)."""
    if isinstance(col, np.ndarray):
        col = pa.chunked_array([pa.array(col, from_pandas=True)])
    if not is_text_type(col.type):
        if pa.types.is_floating(col.type):  # 2.0 -> "2", as a CSV writer would
            as_int = pc.cast(col, pa.int64(), safe=False)
            whole = pc.fill_null(pc.equal(pc.cast(as_int, col.type), col), False)
            col = pc.if_else(whole, pc.cast(as_int, pa.string()), pc.cast(col, pa.string()))
        else:
            col = pc.cast(col, pa.string())
    out = pc.fill_null(pc.utf8_trim_whitespace(col), "").to_numpy()
    return out.astype(str) if len(out) else np.array([], dtype=str)


__all__ = ["Table", "from_frame", "has_gaps", "is_numeric", "is_text_type", "is_parquet", "numeric", "read_table", "text",
           "text_cells"]
