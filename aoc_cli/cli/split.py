"""``aoc split NAME --test 0.2 --seed 0``: one cohort, a training and a test corpus
(:func:`aoc_cli.api.split`)."""

from __future__ import annotations

from typing import Optional

import typer

import aoc_cli
from aoc_cli.cli.common import CorpusArgument, FormatOption, OverwriteOption, state
from aoc_cli.cli.output import resolve_format, write_records


def register(app: typer.Typer) -> None:
    @app.command("split")
    def split(
        name: CorpusArgument,
        test: float = typer.Option(0.2, "--test", help="Share of the stays in the test part."),
        seed: int = typer.Option(0, "--seed", help="Seed of the draw."),
        by: Optional[str] = typer.Option(
            None, "--by", help="A tag (hospital, year): each of its values falls in one part."),
        train_name: Optional[str] = typer.Option(
            None, "--train-name", help="Name of the training corpus (default NAME-train)."),
        test_name: Optional[str] = typer.Option(
            None, "--test-name", help="Name of the test corpus (default NAME-test)."),
        overwrite: OverwriteOption = False,
        fmt: FormatOption = None,
    ) -> None:
        """Split corpus NAME into NAME-train and NAME-test: imputation medians and dose bins
        fitted on the training stays alone; the split recorded in both."""
        fmt = resolve_format(fmt)
        names = (train_name or f"{name}-train", test_name or f"{name}-test")
        result = aoc_cli.split(name, test=test, seed=seed, by=by, names=names,
                               store=state.store, overwrite=overwrite)
        write_records(result.rows(), fmt, title=f"split {name}")
