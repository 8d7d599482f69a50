"""The one place that knows the output formats.

Data goes to stdout, messages and progress to stderr. Every command that prints data goes
through :func:`write_records` (a list of rows) or :func:`write_object` (one object), so
``--format table|json|jsonl|csv`` behaves the same everywhere and ``| jq`` always works.
"""

from __future__ import annotations

import csv
import io
import json
import sys
from typing import Any, Sequence

from rich.console import Console
from rich.progress import (
    BarColumn,
    MofNCompleteColumn,
    Progress,
    TextColumn,
    TimeElapsedColumn,
    TimeRemainingColumn,
)
from rich.table import Table

from aoc_cli.errors import BadSetting, param
from aoc_cli.report import to_jsonable

FORMATS = ("table", "json", "jsonl", "csv")

#: stderr console for messages, progress bars and warnings.
console = Console(stderr=True)


def _stdout_console() -> Console:
    # Created per call so that a redirected sys.stdout (tests, pipes) is honoured.
    return Console(file=sys.stdout, soft_wrap=False, width=None if sys.stdout.isatty() else 200)


def resolve_format(fmt: str | None) -> str:
    """``None`` means: a table on a terminal, JSON when stdout is a pipe or a file."""
    if fmt is None:
        return "table" if sys.stdout.isatty() else "json"
    fmt = fmt.lower()
    if fmt not in FORMATS:
        raise BadSetting("format", fmt, f"unknown {param('format')} {fmt!r}: use one of "
                         f"{', '.join(FORMATS)}")
    return fmt


def _cell(value: Any, table: bool = False) -> str:
    """A CSV cell (full precision; lists and dicts as compact JSON) or, with ``table``, a table
    cell: floats to 6 significant digits, also inside lists and dicts (an action vector reads
    ``[0.742403, 0.736766]``)."""
    value = to_jsonable(value)
    if value is None:
        return ""
    if isinstance(value, float):
        return f"{value:.6g}"
    if isinstance(value, (list, dict)):
        if table:
            return _short(value)
        return json.dumps(value, separators=(",", ":"))
    return str(value)


def _short(value: Any) -> str:
    if isinstance(value, float):
        return f"{value:.6g}"
    if isinstance(value, list):
        return "[" + ", ".join(_short(v) for v in value) + "]"
    if isinstance(value, dict):
        return "{" + ", ".join(f"{k}: {_short(v)}" for k, v in value.items()) + "}"
    return json.dumps(value)


def write_records(
    records: Sequence[dict],
    fmt: str | None,
    columns: Sequence[str] | None = None,
    title: str | None = None,
    out=None,
) -> None:
    """Write rows (dicts sharing keys) in the chosen format to stdout."""
    out = out or sys.stdout
    fmt = resolve_format(fmt)
    records = [to_jsonable(r) for r in records]
    if columns is None:
        columns = list(dict.fromkeys(k for r in records for k in r))
    if fmt == "json":
        json.dump(records, out, indent=2)
        out.write("\n")
    elif fmt == "jsonl":
        for r in records:
            out.write(json.dumps(r) + "\n")
    elif fmt == "csv":
        buf = io.StringIO()
        writer = csv.writer(buf, lineterminator="\n")
        writer.writerow(columns)
        for r in records:
            writer.writerow([_cell(r.get(c)) for c in columns])
        out.write(buf.getvalue())
    else:
        table = Table(title=title)
        for c in columns:
            table.add_column(str(c), overflow="fold")
        for r in records:
            table.add_row(*[_cell(r.get(c), table=True) for c in columns])
        _stdout_console().print(table)
    out.flush()


def write_object(obj: dict, fmt: str | None, title: str | None = None, out=None) -> None:
    """Write one object: JSON object, one JSONL line, a one-row CSV or a key/value table."""
    out = out or sys.stdout
    fmt = resolve_format(fmt)
    obj = to_jsonable(obj)
    if fmt == "json":
        json.dump(obj, out, indent=2)
        out.write("\n")
    elif fmt == "jsonl":
        out.write(json.dumps(obj) + "\n")
    elif fmt == "csv":
        write_records([obj], "csv", out=out)
        return
    else:
        table = Table(title=title, show_header=False)
        table.add_column("key", style="bold")
        table.add_column("value", overflow="fold")
        for k, v in obj.items():
            table.add_row(str(k), _cell(v, table=True))
        _stdout_console().print(table)
    out.flush()


def message(text: str) -> None:
    """A message for the person at the terminal (stderr)."""
    console.print(text, highlight=False)


def progress(transient: bool = False) -> Progress:
    """A rich progress bar on stderr: ``with progress() as p: t = p.add_task("...", total=n)``.

    Shown when stderr is a terminal (or ``AOC_PROGRESS=1``); silent in pipes and tests, and
    with ``AOC_PROGRESS=0`` (as ``scripts/transcripts.py`` runs commands).
    """
    return Progress(
        TextColumn("[progress.description]{task.description}"),
        BarColumn(),
        MofNCompleteColumn(),
        TimeElapsedColumn(),
        TimeRemainingColumn(),
        console=console,
        transient=transient,
        disable=_progress_setting() == "0"
        or (not console.is_terminal and _progress_setting() != "1"),
    )


class ProgressBar:
    """:class:`aoc_cli.progress.Progress` drawn as a rich bar on stderr (shown as
    :func:`progress` is): ``with ProgressBar("label") as p: work(..., progress=p)``; the
    reports set the bar's count, total and label. The bar is drawn from the first report on,
    so work that fails its checks before reporting (bad input) draws none."""

    def __init__(self, label: str = "", total: float | None = None, transient: bool = False):
        self._bars, self._label, self._total = progress(transient), label, total
        self._task = None

    def __enter__(self) -> "ProgressBar":
        return self

    def __exit__(self, *exc) -> None:
        if self._task is not None:
            self._bars.__exit__(*exc)

    def __call__(self, done: float, total: float | None = None, label: str | None = None) -> None:
        if self._task is None:
            self._bars.__enter__()
            self._task = self._bars.add_task(self._label, total=self._total)
        changes: dict = {"completed": done}
        if total is not None:
            changes["total"] = total
        if label is not None:
            changes["description"] = label
        self._bars.update(self._task, **changes)


def _progress_setting() -> str:
    """``AOC_PROGRESS``: "1" shows progress bars even in a pipe, "0" never shows them."""
    import os

    return os.environ.get("AOC_PROGRESS", "")
