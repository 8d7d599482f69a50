"""``aoc verify [NAME...]``: recompute every checksum the store recorded; one row per file
(``ok`` / ``damaged`` / ``missing`` / ``unrecorded``), exit 2 when anything is damaged or
missing. First it clears the temporaries of dead writers anywhere in the store and orphaned
lock files, one ``cleared`` row each. The work is in :mod:`aoc_cli.store.verify`."""

from __future__ import annotations

from typing import Annotated, List, Optional

import typer

from aoc_cli.cli.common import FormatOption, get_store
from aoc_cli.errors import AocError


def register(app: typer.Typer) -> None:
    @app.command("verify")
    def verify(
        names: Annotated[Optional[List[str]], typer.Argument(
            help="Corpora to check (default: every corpus of the store).",
            show_default=False)] = None,
        fmt: FormatOption = None,
    ) -> None:
        """Check every file of the store against the checksums recorded when it was written."""
        from aoc_cli.report.output import message, progress, write_records
        from aoc_cli.store.verify import cleared_rows, corpora_to_verify, verify_corpus

        store = get_store()
        chosen = corpora_to_verify(store, list(names or []))
        cleared = cleared_rows(store)
        if not chosen:
            message(f"no corpora in {store.root}: nothing to verify")
        rows = list(cleared)
        with progress(transient=True) as bar:
            task = bar.add_task("verify", total=len(chosen))
            for name in chosen:
                bar.update(task, description=f"verify {name}")
                rows += verify_corpus(store, name)
                bar.advance(task)
        write_records(rows, fmt, columns=["corpus", "file", "status", "detail"],
                      title=f"aoc verify ({store.root})")
        bad = [r for r in rows if r["status"] in ("damaged", "missing")]
        if bad:
            raise AocError(f"{len(bad)} of {len(rows) - len(cleared)} files damaged or missing, first "
                           f"{bad[0]['corpus']}/{bad[0]['file']} ({bad[0]['detail']}): "
                           "re-ingest or re-collect a damaged corpus with --overwrite, "
                           "re-train a damaged model with --overwrite, re-run `aoc index` "
                           "for damaged beliefs or an index")
        if cleared:
            message(f"cleared {len(cleared)} leftovers of dead writers")
        message(f"verified {len(rows) - len(cleared)} files of {len(chosen)} corpora: all "
                "intact")
