"""``aoc ingest PATH --name NAME``: read a dataset file or folder into a corpus of the store."""

from __future__ import annotations

from pathlib import Path
from typing import List, Optional

import typer

import aoc_cli
from aoc_cli.cli.common import FormatOption, parse_key_values, state
from aoc_cli.report.output import ProgressBar, resolve_format, write_object


def _names(text: Optional[str]) -> Optional[list[str]]:
    return [c.strip() for c in text.split(",") if c.strip()] if text else None


def register(app: typer.Typer) -> None:
    @app.command("ingest")
    def ingest(
        path: str = typer.Argument(..., help="Dataset file or folder, or a Minari dataset id."),
        name: str = typer.Option(..., "--name", help="Name of the corpus to create."),
        source_format: Optional[str] = typer.Option(
            None, "--from", help="Input format: minari|d4rl|d3rlpy|npz|csv (default: detect)."),
        tag: Optional[List[str]] = typer.Option(
            None, "--tag", help="KEY=VALUE: a constant tag on every row (repeatable)."),
        tag_column: Optional[List[str]] = typer.Option(
            None, "--tag-column", help="A source column (CSV column, info key) to use as a tag "
            "(repeatable)."),
        reward_free: bool = typer.Option(False, "--reward-free", help="Store no rewards."),
        overwrite: bool = typer.Option(False, "--overwrite", help="Replace an existing corpus."),
        append: bool = typer.Option(
            False, "--append", help="Add the episodes to an existing corpus (same spaces)."),
        drop_nonfinite: bool = typer.Option(
            False, "--drop-nonfinite", help="Drop episodes holding NaN or inf values."),
        discrete_actions: bool = typer.Option(
            False, "--discrete-actions", help="Integer-valued actions are discrete choices."),
        columns: Optional[Path] = typer.Option(
            None, "--columns", help="CSV: JSON file mapping roles to columns (id, time, "
            "observations, actions, reward, terminal, tags, static_id)."),
        obs_columns: Optional[str] = typer.Option(
            None, "--obs-columns", help="CSV: observation columns, comma-separated (globs ok)."),
        act_columns: Optional[str] = typer.Option(
            None, "--act-columns", help="CSV: action columns, comma-separated (globs ok)."),
        reward_column: Optional[str] = typer.Option(None, "--reward-column", help="CSV."),
        id_column: Optional[str] = typer.Option(
            None, "--id-column", help="CSV: episode (patient) id column."),
        time_column: Optional[str] = typer.Option(None, "--time-column", help="CSV."),
        terminal_column: Optional[str] = typer.Option(None, "--terminal-column", help="CSV."),
        static: Optional[Path] = typer.Option(
            None, "--static", help="CSV of static per-episode features, one row per id."),
        fmt: FormatOption = None,
    ) -> None:
        """Read a dataset (Minari, D4RL HDF5, d3rlpy, NPZ, CSV) into corpus NAME."""
        resolve_format(fmt)
        options = dict(
            tags=parse_key_values(tag, "--tag"), tag_columns=list(tag_column or []),
            reward_free=reward_free, drop_nonfinite=drop_nonfinite,
            discrete_actions=discrete_actions, columns_file=columns,
            obs_columns=_names(obs_columns), act_columns=_names(act_columns),
            reward_column=reward_column, id_column=id_column, time_column=time_column,
            terminal_column=terminal_column, static=static,
        )
        with ProgressBar(f"ingest {name}") as bar:
            result = aoc_cli.ingest(path, name, store=state.store, fmt=source_format,
                                    options=options, overwrite=overwrite, append=append,
                                    progress=bar)
        write_object(result.summary(), fmt, title=f"ingested {name}")
