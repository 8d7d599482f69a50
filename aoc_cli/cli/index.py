"""`aoc index NAME`: beliefs of every corpus row and the nearest-neighbour index."""

from __future__ import annotations

from typing import Annotated, List, Optional

import typer

import aoc_cli
from aoc_cli.cli.common import (CorpusArgument, FormatOption, IndexKind, ModelOption,
                                StepCandidates, choice, parse_rates, state)
from aoc_cli.cli.fields import from_field
from aoc_cli.errors import AocError
from aoc_cli.index.search.config import IndexConfig
from aoc_cli.cli.output import ProgressBar, write_object
from aoc_cli.settings import SMALL_LOG_ROWS
from aoc_cli.store import DEFAULT_INDEX


def register(app: typer.Typer) -> None:
    @app.command("index")
    def index_command(
        name: CorpusArgument,
        model: ModelOption = None,
        kind: IndexKind = from_field(IndexConfig, "kind"),
        index_id: Annotated[str, typer.Option(
            "--index", "--index-id",
            help="Name of the index (derived indexes need their own).")] = DEFAULT_INDEX,
        episode_rate: Annotated[Optional[List[str]], typer.Option(
            "--episode-rate", "--resample",
            help="TAG=VALUE:RATE, a derived index keeping whole episodes of that tag value: "
                 "policy=pi1:4 repeats them four times, policy=pi1:0.5 keeps a random half "
                 "of them (--resample: the older name).")] = None,
        subsample: Annotated[Optional[List[str]], typer.Option(
            "--subsample", help="TAG=VALUE:RATE, an episode rate of at most 1 (kept for "
                                "older scripts; same as --episode-rate).")] = None,
        seed: int = from_field(IndexConfig, "seed", more="Also of sub-sampling and of the "
                                                         "typical-residual sample."),
        neighbours: Annotated[Optional[StepCandidates], typer.Option(
            "--neighbours", case_sensitive=False,
            help="Step 1's neighbour rows: auto (the nearest rows of each action for an "
                 f"imitation model of discrete actions on up to {SMALL_LOG_ROWS:,} rows, else "
                 "the k nearest rows), nearest (the paper's k = 2 (d_b + 1) nearest rows) or "
                 "per_action. [default: auto]")] = None,
        old_neighbours: Annotated[Optional[StepCandidates], typer.Option(
            "--candidates", case_sensitive=False, hidden=True,
            help="The older name of --neighbours.")] = None,
        fmt: FormatOption = None,
    ) -> None:
        """Compute every row's belief and build the index the controller searches."""
        if neighbours is not None and old_neighbours is not None \
                and neighbours != old_neighbours:
            raise AocError("--neighbours and --candidates (its older name) differ: give one")
        rule = neighbours or old_neighbours or StepCandidates.auto
        rates = parse_rates(episode_rate, "--episode-rate")
        with ProgressBar("index") as p:
            built = aoc_cli.build_index(name, model, store=state.store, kind=choice(kind),
                                        index_id=index_id, episode_rates=rates,
                                        subsample=parse_rates(subsample, "--subsample"), seed=seed,
                                        neighbours=choice(rule), progress=p)
        meta = built.index.meta
        write_object(built.summary(), fmt, title=f"index {meta['index_id']} of {built.corpus}")
