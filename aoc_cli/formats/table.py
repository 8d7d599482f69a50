"""Tables read on pyarrow: CSV (``.tsv``: tab-separated; ``.gz``: gzip-compressed), Parquet,
and in-memory Arrow tables or pandas / polars DataFrames, as columns of Arrow arrays; and
those columns as numbers or text. What the tabular log reader (:mod:`aoc_cli.formats.csv`)
and its static covariates (:mod:`aoc_cli.formats.static`) build on.

pyarrow's readers are typed and null-aware: an empty cell of a number column is a null (NaN
once converted), a column holding text stays text. A CSV is streamed block by block first
(the types inferred from the first block): each block's number columns (integers, floats,
booleans) are written straight into one float64 numpy array per column, made at the row count
estimated from the file's first MB (grown if short), and its other columns kept as Arrow
chunks; so the peak
memory is the columns plus a block, never the whole Arrow table beside numpy copies of it.
When streaming fails (a later block holds what the first one's types cannot, a quoted line
break) the whole file is read at once, allowing quoted line breaks (a spreadsheet's free-text
notes), and only when that fails too is the bad row found, with Python's ``csv`` module, to
name it. A column is then either such a numpy array or an Arrow chunked array (Parquet,
frames, the whole-file read, text); :func:`numeric`, :func:`text`, :func:`has_gaps` and
:func:`is_numeric` take both.
"""

from __future__ import annotations

import contextlib
import csv
import gzip
import io
import os
import zlib
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.compute as pc
import pyarrow.csv as pacsv
import pyarrow.parquet as pq

from aoc_cli.errors import AocError

#: Bytes per block of pyarrow's CSV reader. The reader reads ahead several blocks, and its
#: memory pool keeps what they held: on the 58 MB cohort (benchmarks/perf/ingest.py) 256 KB
#: blocks left ~30 MB resident after the read, 1 MB ~40 MB and 4 MB ~85 MB, for the same CPU
#: time within the noise (4 MB the slowest).
BLOCK_BYTES = 256 << 10
#: A plain CSV of at least this size is read as two halves in two threads (:func:`_halves`).
SPLIT_BYTES = 8 << 20
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
                return _streamed(path, parse, convert)
            return pacsv.read_csv(path, read_options=pacsv.ReadOptions(
                block_size=BLOCK_BYTES), parse_options=parse, convert_options=convert)
        except pa.ArrowInvalid as err:
            failure = err
        except (OSError, pa.ArrowException) as err:
            raise AocError(f"cannot read {path} as CSV ({_first(err)}); a .gz file must be "
                           "gzip-compressed CSV") from None
    _name_bad_row(path, delimiter, len(header))
    raise AocError(f"cannot read {path} as CSV ({_first(failure)}): fix the file")


def _as_numbers(t) -> bool:
    """Columns the streamed reader makes float64 numpy arrays at once (what :func:`numeric`
    would make of them): integers, floats, booleans."""
    return pa.types.is_integer(t) or pa.types.is_floating(t) or pa.types.is_boolean(t)


def _rows_estimate(path: Path) -> int | None:
    """About how many rows a plain file holds, from the line breaks of its first MB (~10%
    over; a gzip file: None). Only a first size: the arrays grow if it is short, and pages
    never written are never resident."""
    if path.suffix.lower() == ".gz":
        return None
    size = path.stat().st_size
    with open(path, "rb") as fh:
        sample = fh.read(1 << 20)
    return int(size * max(sample.count(b"\n"), 1) / max(len(sample), 1) * 1.1) + 1024


class _Numbers:
    """One numeric column as it streams in: written into one float64 array made at the
    estimated row count, grown 1.5x (one copy) when the rows outrun it; ``fixed`` (two
    halves writing into one array): made at a true bound, never grown."""

    def __init__(self, capacity: int, fixed: bool = False):
        self.out = np.empty(capacity)
        self.fixed = fixed

    def add(self, col: pa.Array, start: int) -> None:
        if not pa.types.is_float64(col.type):
            col = pc.cast(col, pa.float64())
        values, valid = arrow_values(col)
        end = start + len(values)
        if end > len(self.out):
            if self.fixed:
                raise AssertionError("more rows than the file's line breaks")
            grown = np.empty(max(end, len(self.out) * 3 // 2))
            grown[:start] = self.out[:start]
            self.out = grown
        self.out[start:end] = values
        if valid is not None:
            self.out[start:end][~valid] = np.nan  # empty cells

    def array(self, n: int) -> np.ndarray:
        return self.out[:n]


def arrow_values(col: pa.Array) -> tuple[np.ndarray, np.ndarray | None]:
    """(values, valid) of one fixed-width Arrow array (float64, int32, ...) read from its
    buffers: a view of its values and, when it has nulls, (N,) bool true where present (its
    null cells' values are undefined). Not ``to_numpy``: pyarrow's conversion goes through its
    pandas layer and imports pandas on first use (~0.3-0.7 s and ~50 MB in a fresh process)."""
    n, off = len(col), col.offset
    if n == 0:
        return np.zeros(0, col.type.to_pandas_dtype()), None
    validity, data = col.buffers()[:2]
    values = np.frombuffer(data, col.type.to_pandas_dtype(), count=n + off)[off:]
    if not col.null_count:
        return values, None
    bits = np.unpackbits(np.frombuffer(validity, np.uint8), count=n + off, bitorder="little")
    return values, bits[off:].view(bool)


@dataclass
class _Halves:
    """A plain CSV that can be read as two halves: ``middle`` the offset just after the line
    break nearest its middle, ``lines`` its line breaks + 1 (a bound on its rows: the last
    line may lack its break) and ``before`` the first half's line breaks (its header and rows:
    a bound on its rows, + 1, where the second half's rows are written)."""

    middle: int
    lines: int
    before: int


def _halves(path: Path) -> _Halves | None:
    """How to cut a plain CSV in two: when it is at least :data:`SPLIT_BYTES`, the machine has
    two cores or more and the file holds no quote character (then every line break ends a row
    or is a blank line; a quoted field may hold one). Else None: one stream."""
    if path.suffix.lower() == ".gz" or (os.cpu_count() or 1) < 2:
        return None
    size = path.stat().st_size
    if size < SPLIT_BYTES:
        return None
    buf, lines, before, middle = bytearray(1 << 20), 1, 0, None
    with open(path, "rb", buffering=0) as fh:
        while k := fh.readinto(buf):
            if buf.find(b'"', 0, k) >= 0:
                return None
            start = fh.tell() - k
            if middle is None and start + k > size // 2:
                at = buf.find(b"\n", max(size // 2 - start, 0), k)
                if at >= 0:
                    middle = start + at + 1
                    before = lines - 1 + buf.count(b"\n", 0, at + 1)
            lines += buf.count(b"\n", 0, k)
    if middle is None or middle >= size:
        return None
    return _Halves(middle, lines, before)


def _streamed(path: Path, parse, convert) -> Table:
    """A CSV read block by block (the types inferred from the first block): each numeric
    column converted at once into one float64 array (made at the estimated row count),
    other columns kept as Arrow chunks. So the parse never holds more than a block beside the
    columns (memory about the columns' size; the whole file in Arrow, then numpy copies of its
    columns, would be twice that). A file :func:`_halves` can cut is read as two halves in two
    threads into the same arrays (the second half from the first's bound on, with the first's
    column names and types, as one stream would read it), then its rows moved up to follow
    the first half's."""
    read = pacsv.ReadOptions(block_size=BLOCK_BYTES)
    halves = _halves(path)
    with contextlib.ExitStack() as stack:
        first = stack.enter_context(pacsv.open_csv(
            path if halves is None else _Range(path, 0, halves.middle), read_options=read,
            parse_options=parse, convert_options=convert))
        schema = first.schema
        chunks: dict[int, list] = {i: [] for i, f in enumerate(schema)
                                   if not _as_numbers(f.type)}
        numbers = {i: _Numbers(halves.lines, fixed=True) for i in range(len(schema))
                   if i not in chunks} if halves is not None else {}
        later = None
        if halves is not None:
            second = stack.enter_context(pacsv.open_csv(
                _Range(path, halves.middle, path.stat().st_size), parse_options=parse,
                read_options=pacsv.ReadOptions(block_size=BLOCK_BYTES,
                                               column_names=schema.names),
                convert_options=_typed(convert, schema)))
            pool = stack.enter_context(ThreadPoolExecutor(max_workers=1))
            later = pool.submit(_consume, second, numbers, {i: [] for i in chunks},
                                halves.before, None)
        n = _consume(first, numbers, chunks, 0, _rows_estimate(path))
        if later is not None:
            n_second, more = later.result()
            for col in numbers.values():  # close the gap between the halves
                col.out[n:n + n_second] = col.out[halves.before:halves.before + n_second]
            for i, parts in more.items():
                chunks[i] += parts
            n += n_second
    pa.default_memory_pool().release_unused()  # the blocks' buffers, kept by the pool
    names = [str(h).strip() for h in schema.names]
    _check_names(names, str(path))
    cols: dict = {}
    for i, name in enumerate(names):
        if i in chunks:
            cols[name] = pa.chunked_array(chunks.pop(i), type=schema.field(i).type)
        else:
            cols[name] = numbers[i].array(n) if i in numbers else np.zeros(0)
    return Table(str(path), names, cols, n)


def _consume(reader, numbers: dict, chunks: dict, offset: int, estimate: int | None):
    """Read a streaming reader to its end: each block's numeric columns into ``numbers``
    from row ``offset`` on (made at ``estimate`` rows, or the first block's x 64, when
    empty), its other columns appended to ``chunks``. Returns the rows read (and, from row
    ``offset`` > 0, the chunks too: the second half)."""
    n = 0
    for batch in reader:
        if not numbers:
            capacity = estimate or 64 * batch.num_rows
            numbers.update({i: _Numbers(capacity) for i in range(batch.num_columns)
                            if i not in chunks})
        for i, col in numbers.items():
            col.add(batch.column(i), offset + n)
        for i, parts in chunks.items():
            parts.append(batch.column(i))
        n += batch.num_rows
    return (n, chunks) if offset else n


def _typed(convert, schema):
    """``convert`` with every column's type set to ``schema``'s (the second half's reader
    infers nothing: it reads what the first half's types say, as one stream would)."""
    return pacsv.ConvertOptions(
        column_types={f.name: f.type for f in schema},
        strings_can_be_null=convert.strings_can_be_null,
        quoted_strings_can_be_null=convert.quoted_strings_can_be_null)


class _Range(io.RawIOBase):
    """Bytes [start, stop) of a file, as a readable stream (one half of a CSV)."""

    def __init__(self, path: Path, start: int, stop: int):
        super().__init__()
        self._fh = open(path, "rb", buffering=0)
        self._fh.seek(start)
        self._left = stop - start

    def readable(self) -> bool:
        return True

    def readinto(self, b) -> int:
        if self._left <= 0:
            return 0
        k = self._fh.readinto(memoryview(b)[:min(len(b), self._left)])
        self._left -= k
        return k

    def close(self) -> None:
        self._fh.close()
        super().close()


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
