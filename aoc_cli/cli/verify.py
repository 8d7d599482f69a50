"""``aoc verify [NAME...]``: recompute every checksum the store recorded; one row per file
(``ok`` / ``damaged`` / ``missing`` / ``unrecorded``), exit 2 when anything is damaged or
missing. First it clears the temporaries of dead writers anywhere in the store and orphaned
lock files, one ``cleared`` row each. The work is in :func:`aoc_cli.api.verify`."""

from __future__ import annotations

from typing import Annotated, List, Optional

import typer

import aoc_cli
from aoc_cli.cli.common import FormatOption, state
from aoc_cli.errors import AocError
from aoc_cli.cli.output import ProgressBar, message, write_records


def register(app: typer.Typer) -> None:
    @app.command("verify")
    def verify(
        names: Annotated[Optional[List[str]], typer.Argument(
            help="Corpora to check (default: every corpus of the store).",
            show_default=False)] = None,
        fmt: FormatOption = None,
    ) -> None:
        """Check every file of the store against the checksums recorded when it was written."""
        with ProgressBar("verify", transient=True) as bar:
            done = aoc_cli.verify(names, store=state.store, progress=bar)
        if not done.corpora:
            message(f"no corpora in {done.root}: nothing to verify")
        write_records(done.rows, fmt, columns=["corpus", "file", "status", "detail"],
                      title=f"aoc verify ({done.root})")
        if done.failure():
            raise AocError(done.failure())
        if done.cleared:
            message(f"cleared {done.cleared} leftovers of dead writers")
        message(f"verified {done.files} files of {len(done.corpora)} corpora: all intact")
