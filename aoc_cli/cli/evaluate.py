"""`aoc evaluate NAME --data HELD_OUT`: decide every logged step of a corpus and score the
decisions against what was logged. Parses and prints only; the work is in
:func:`aoc_cli.api.evaluate`."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated, Optional

import typer

from aoc_cli.cli.common import (CandidatesOption, CorpusArgument, EpsilonOption,
                                FormatOption, IndexOption, KOption, MinSupportOption, ModelOption,
                                RayAddressOption, SupportPenaltyOption, WithoutEpisodesOption,
                                WithoutOption, WorkersOption, parse_episodes,
                                parse_selection, state)
from aoc_cli.errors import warn
from aoc_cli.report import ProgressBar, resolve_format
from aoc_cli.report.evaluate_view import write_evaluation
from aoc_cli.settings import SMALL_LOG_ROWS
from aoc_cli.store import DEFAULT_INDEX


def register(app: typer.Typer) -> None:
    @app.command("evaluate")
    def evaluate_command(
        name: CorpusArgument,
        data: Annotated[str, typer.Option(
            "--data", help="Held-out corpus to score (same spaces), or NAME itself: each "
                           "episode is then decided without its own rows.")],
        baselines: Annotated[str, typer.Option(
            "--baselines", help="Baselines on the same steps, comma-separated: knn (nearest "
                                "rows on standardised inputs), bc (the model's own head); none "
                                "for neither.")] = "knn,bc",
        steps_file: Annotated[Optional[Path], typer.Option(
            "--steps", help="Write one JSON record per step to this JSONL file.")] = None,
        model: ModelOption = None,
        index_id: IndexOption = DEFAULT_INDEX,
        candidates: CandidatesOption = None,
        epsilon: EpsilonOption = None,
        k: KOption = None,
        min_support: MinSupportOption = None,
        support_penalty: SupportPenaltyOption = None,
        exact: Annotated[Optional[bool], typer.Option(
            "--exact/--ivf", help="Search the index exactly for every step, or an IVF structure "
                                  "built for the run (default: exact up to "
                                  f"{SMALL_LOG_ROWS:,} corpus rows, IVF beyond: ~10x faster, "
                                  "recall of the nearest rows ~0.9999).")] = None,
        seed: Annotated[int, typer.Option(
            "--seed", help="Seed of the candidates (value mode, continuous actions), the "
                           "bootstrap and FQE.")] = 0,
        ope_names: Annotated[Optional[str], typer.Option(
            "--ope", help="Offline policy evaluation of the decisions (value mode): pdwis, "
                          "wdr, fqe, comma-separated, or none (default: all three when the "
                          "held-out log has rewards and discrete actions).")] = None,
        propensity: Annotated[Optional[str], typer.Option(
            "--propensity", help="Corpus column of the behaviour's probability of each "
                                 "logged action (default: 'propensity' when the log has it, "
                                 "else an imitation model estimates them).")] = None,
        ope_gamma: Annotated[float, typer.Option(
            "--ope-gamma", help="Discount of the value the OPE estimates (1: the mean "
                                "undiscounted return of an episode).")] = 1.0,
        fqe_steps: Annotated[Optional[int], typer.Option(
            "--fqe-steps", help="Gradient steps of fitted Q evaluation (default: about 30 "
                                "passes over the log, 1,500 to 6,000).")] = None,
        fqe_refits: Annotated[Optional[int], typer.Option(
            "--fqe-refits", help="Refits on resampled episodes behind FQE's interval, each a "
                                 "fifth of the fit's steps (default 10; 0: one fit, the "
                                 "interval then leaves the model's own error out).")] = None,
        workers: WorkersOption = None,
        ray_address: RayAddressOption = None,
        without: WithoutOption = None,
        without_episodes: WithoutEpisodesOption = None,
        fmt: FormatOption = None,
    ) -> None:
        """Decide every logged step of a held-out corpus in batches and score the decisions
        (accuracy, AUC, calibration or value R^2; residuals; baselines on the same steps)."""
        from aoc_cli import api  # here: keeps `aoc --help` and bad input from importing torch

        fmt = resolve_format(fmt)
        with ProgressBar("evaluate", transient=True) as bar:
            summary = api.evaluate(
                name, data, store=state.store, baselines=[b.strip() for b in baselines.split(",")],
                steps_file=steps_file, model=model, index_id=index_id, candidates=candidates,
                epsilon=epsilon, k=k, min_support=min_support, support_penalty=support_penalty,
                exact=exact, seed=seed, ope=ope_names, propensity=propensity, ope_gamma=ope_gamma,
                fqe_steps=fqe_steps, fqe_refits=fqe_refits, workers=workers,
                ray_address=ray_address,
                without=parse_selection(without, "--without"),
                without_episodes=parse_episodes(without_episodes), progress=bar)
        for text in summary.get("ope_warnings", []):
            warn(text)
        write_evaluation(summary, fmt)
