"""A plain or gzip CSV streamed block by block on pyarrow into numpy columns: the reader under
:func:`aoc_cli.formats.table.read_table` (which falls back to reading the whole file and names
a bad row when streaming fails).

Each block's number columns (integers, floats, booleans) are written straight into one float64
array per column, made at the row count estimated from the file's first MB (grown if short);
its other columns are kept as Arrow chunks. So the peak memory is the columns plus a block,
never the whole Arrow table beside numpy copies of it. A large plain file without quotes is
read as two halves in two threads (:func:`halves`): pyarrow's streaming reader uses one.
Numbers come from Arrow's buffers (:func:`arrow_values`), not ``to_numpy``, which imports
pandas.
"""

from __future__ import annotations

import contextlib
import io
import os
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.compute as pc
import pyarrow.csv as pacsv

#: Bytes per block of pyarrow's CSV reader. The reader reads ahead several blocks, and its
#: memory pool keeps what they held: on the 58 MB cohort (benchmarks/perf/ingest.py) 256 KB
#: blocks left ~30 MB resident after the read, 1 MB ~40 MB and 4 MB ~85 MB, for the same CPU
#: time within the noise (4 MB the slowest).
BLOCK_BYTES = 256 << 10
#: A plain CSV of at least this size is read as two halves in two threads (:func:`halves`).
SPLIT_BYTES = 8 << 20


def as_numbers(t) -> bool:
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
class Halves:
    """A plain CSV that can be read as two halves: ``middle`` the offset just after the line
    break nearest its middle, ``lines`` its line breaks + 1 (a bound on its rows: the last
    line may lack its break) and ``before`` the first half's line breaks (its header and rows:
    a bound on its rows, + 1, where the second half's rows are written)."""

    middle: int
    lines: int
    before: int


def halves(path: Path) -> Halves | None:
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
    return Halves(middle, lines, before)


def streamed(path: Path, parse, convert) -> tuple[list[str], list, int]:
    """A CSV read block by block (the types inferred from the first block): each numeric
    column converted at once into one float64 array (made at the estimated row count),
    other columns kept as Arrow chunks. So the parse never holds more than a block beside the
    columns (memory about the columns' size; the whole file in Arrow, then numpy copies of its
    columns, would be twice that). A file :func:`halves` can cut is read as two halves in two
    threads into the same arrays (the second half from the first's bound on, with the first's
    column names and types, as one stream would read it), then its rows moved up to follow
    the first half's. Returns the header as read, the columns in its order (an (n,) float64
    array or an Arrow chunked array each) and the rows n."""
    read = pacsv.ReadOptions(block_size=BLOCK_BYTES)
    cut = halves(path)
    with contextlib.ExitStack() as stack:
        first = stack.enter_context(pacsv.open_csv(
            path if cut is None else _Range(path, 0, cut.middle), read_options=read,
            parse_options=parse, convert_options=convert))
        schema = first.schema
        chunks: dict[int, list] = {i: [] for i, f in enumerate(schema)
                                   if not as_numbers(f.type)}
        numbers = {i: _Numbers(cut.lines, fixed=True) for i in range(len(schema))
                   if i not in chunks} if cut is not None else {}
        later = None
        if cut is not None:
            second = stack.enter_context(pacsv.open_csv(
                _Range(path, cut.middle, path.stat().st_size), parse_options=parse,
                read_options=pacsv.ReadOptions(block_size=BLOCK_BYTES,
                                               column_names=schema.names),
                convert_options=_typed(convert, schema)))
            pool = stack.enter_context(ThreadPoolExecutor(max_workers=1))
            later = pool.submit(_consume, second, numbers, {i: [] for i in chunks},
                                cut.before, None)
        n = _consume(first, numbers, chunks, 0, _rows_estimate(path))
        if later is not None:
            n_second, more = later.result()
            for col in numbers.values():  # close the gap between the halves
                col.out[n:n + n_second] = col.out[cut.before:cut.before + n_second]
            for i, parts in more.items():
                chunks[i] += parts
            n += n_second
    pa.default_memory_pool().release_unused()  # the blocks' buffers, kept by the pool
    cols = []
    for i in range(len(schema)):
        if i in chunks:
            cols.append(pa.chunked_array(chunks.pop(i), type=schema.field(i).type))
        else:
            cols.append(numbers[i].array(n) if i in numbers else np.zeros(0))
    return list(schema.names), cols, n


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
