"""``aoc ingest PATH --name NAME``: read a dataset file or folder into a corpus of the store."""

from __future__ import annotations

from enum import Enum
from pathlib import Path
from typing import List, Optional

import typer

import aoc_cli
from aoc_cli.cli.common import FormatOption, parse_key_values, state
from aoc_cli.cli.info import imputed_rows
from aoc_cli.cli.output import ProgressBar, resolve_format, write_object, write_records


def _names(text: Optional[str]) -> Optional[list[str]]:
    return [c.strip() for c in text.split(",") if c.strip()] if text else None


class Impute(str, Enum):
    """``--impute``'s rules (:mod:`aoc_cli.formats.impute`)."""

    hold = "hold"
    median = "median"


def register(app: typer.Typer) -> None:
    @app.command("ingest")
    def ingest(
        path: str = typer.Argument(..., help="Dataset file or folder, or a Minari dataset id."),
        name: str = typer.Option(..., "--name", help="Name of the corpus to create."),
        source_format: Optional[str] = typer.Option(
            None, "--from", help="Input format: minari|d4rl|d3rlpy|npz|csv|parquet (default: detect)."),
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
        impute: Optional[Impute] = typer.Option(
            None, "--impute", help="Fill empty observation cells: hold (the stay's last "
            "measured value, else the median) or median (the corpus's median)."),
        impute_mask: bool = typer.Option(
            False, "--impute-mask", help="Add a 0/1 COL?measured feature per column with gaps."),
        impute_like: Optional[str] = typer.Option(
            None, "--impute-like", help="Fill gaps with corpus NAME's rule and medians "
            "(held-out data: no leak)."),
        outcome: Optional[str] = typer.Option(
            None, "--outcome", help="Column of each stay's outcome (one value per stay): "
            "the reward of its last step; empty: the stay is censored."),
        outcome_reward: Optional[str] = typer.Option(
            None, "--outcome-reward", help="OUTCOME=REWARD pairs, e.g. 1=-1,0=1."),
        bin_actions: Optional[str] = typer.Option(
            None, "--bin-actions", help="COL=BINS,...: cut continuous doses into dose levels "
            "(0: zero dose, the rest at quantiles), e.g. input_4hourly=5,max_dose_vaso=5; "
            "COL=0:50:180:530: the study's own levels, the lower edge of each non-zero one."),
        bin_like: Optional[str] = typer.Option(
            None, "--bin-like", help="Cut the doses at corpus NAME's bin edges."),
        censored_column: Optional[str] = typer.Option(
            None, "--censored-column", help="Column truthy on the rows of a stay cut short "
            "(transfer, end of extract): censored, not ended."),
        allow_role_overlap: bool = typer.Option(
            False, "--allow-role-overlap", help="Keep a column of another role (outcome, "
            "reward, action, censoring, stay id, time) listed among the observations "
            "(refused otherwise: it would leak into the state)."),
        fmt: FormatOption = None,
    ) -> None:
        """Read a dataset (Minari, D4RL HDF5, d3rlpy, NPZ, CSV, Parquet) into corpus NAME."""
        resolve_format(fmt)
        options = dict(
            tags=parse_key_values(tag, "--tag"), tag_columns=list(tag_column or []),
            reward_free=reward_free, drop_nonfinite=drop_nonfinite,
            discrete_actions=discrete_actions, columns_file=columns,
            obs_columns=_names(obs_columns), act_columns=_names(act_columns),
            reward_column=reward_column, id_column=id_column, time_column=time_column,
            terminal_column=terminal_column, static=static,
            impute=impute.value if impute else None, impute_mask=impute_mask,
            impute_like=impute_like, outcome=outcome, outcome_reward=outcome_reward,
            bin_actions=bin_actions, bin_like=bin_like, censored_column=censored_column,
            allow_role_overlap=allow_role_overlap,
        )
        with ProgressBar(f"ingest {name}") as bar:
            result = aoc_cli.ingest(path, name, store=state.store, fmt=source_format,
                                    options=options, overwrite=overwrite, append=append,
                                    progress=bar)
        summary = result.summary()
        if resolve_format(fmt) != "table":
            write_object(summary, fmt, title=f"ingested {name}")
            return
        cells = summary.pop("imputed_cells", None)
        write_object(summary, fmt, title=f"ingested {name}")
        if cells:
            write_records(imputed_rows(cells, summary["rows"]), "table", title="imputed cells")
