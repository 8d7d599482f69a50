"""``aoc export NAME --to minari|d4rl|csv --out PATH``: a corpus out again, for the tools
beside aoc (:func:`aoc_cli.api.export`)."""

from __future__ import annotations

from enum import Enum
from pathlib import Path
from typing import Optional

import typer

import aoc_cli
from aoc_cli.cli.common import (CorpusArgument, ExcludeOption, FormatOption, OverwriteOption,
                                SelectOption, choice, parse_selection, state)
from aoc_cli.errors import AocError
from aoc_cli.cli.output import ProgressBar, resolve_format, write_object


class ExportFormat(str, Enum):
    """``--to``: the format written."""

    minari = "minari"
    d4rl = "d4rl"
    csv = "csv"


def parse_rows(text: Optional[str]) -> Optional[tuple[int, int]]:
    """``"100:200"`` -> (100, 200); a malformed range is an AocError."""
    if text is None:
        return None
    start, sep, end = text.partition(":")
    try:
        if not sep:
            raise ValueError
        return int(start), int(end)
    except ValueError:
        raise AocError(f"--rows expects START:END (e.g. 0:1000), got {text!r}") from None


def register(app: typer.Typer) -> None:
    @app.command("export")
    def export(
        name: CorpusArgument,
        to: ExportFormat = typer.Option(..., "--to", case_sensitive=False,
                                        help="Format: a Minari dataset folder, a D4RL-style "
                                             "HDF5 file, or CSV (one row per step)."),
        out: Path = typer.Option(..., "--out", help="Where to write (outside the store)."),
        select: SelectOption = None,
        exclude: ExcludeOption = None,
        rows: Optional[str] = typer.Option(
            None, "--rows", help="START:END: only corpus rows START to END - 1."),
        static: Optional[Path] = typer.Option(
            None, "--static", help="CSV: write the per-patient covariates (of a corpus read "
                                   "with --static) to this file, one row per id."),
        overwrite: OverwriteOption = False,
        fmt: FormatOption = None,
    ) -> None:
        """Write corpus NAME as Minari, D4RL HDF5 or CSV; `aoc ingest` reads it back exactly."""
        fmt = resolve_format(fmt)
        with ProgressBar(f"export {name}") as bar:
            result = aoc_cli.export(name, choice(to), out, store=state.store,
                                    select=parse_selection(select, "--select"),
                                    exclude=parse_selection(exclude, "--exclude"),
                                    rows=parse_rows(rows),
                                    overwrite=overwrite, static=static, progress=bar)
        write_object(result.summary(), fmt, title=f"exported {name}")
