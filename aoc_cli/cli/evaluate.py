"""`aoc evaluate NAME --data HELD_OUT`: decide every logged step of a corpus and score the
decisions against what was logged. Parses and prints only; the work is in
:func:`aoc_cli.api.evaluate`."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated, Optional

import typer

import aoc_cli
from aoc_cli.cli.common import (CorpusArgument, FormatOption, IndexOption, ModelOption,
                                RayAddressOption, WithoutEpisodesOption, WithoutOption,
                                WorkersOption, deciding, parse_episodes, parse_selection, state)
from aoc_cli.cli.fields import from_field
from aoc_cli.errors import warn
from aoc_cli.ope.evaluate_block import OPESettings
from aoc_cli.cli.output import ProgressBar, message, resolve_format
from aoc_cli.cli.evaluate_view import write_evaluation
from aoc_cli.settings import SMALL_LOG_ROWS
from aoc_cli.store import DEFAULT_INDEX


def register(app: typer.Typer) -> None:
    @app.command("evaluate")
    @deciding
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
        controller: dict = None,
        exact: Annotated[Optional[bool], typer.Option(
            "--exact/--ivf", help="Search the index exactly for every step, or an IVF structure "
                                  "built for the run (default: exact up to "
                                  f"{SMALL_LOG_ROWS:,} corpus rows, IVF beyond: ~10x faster, "
                                  "recall of the nearest rows ~0.9999).")] = None,
        seed: int = from_field(OPESettings, "seed",
                               more="Also of the candidates (value mode, continuous actions)."),
        ope_names: Optional[str] = from_field(
            OPESettings, "estimators",
            given="{default} when the held-out log has rewards and discrete actions"),
        propensity: Optional[str] = from_field(OPESettings, "propensity"),
        ope_gamma: float = from_field(OPESettings, "gamma"),
        fqe_steps: Optional[int] = from_field(OPESettings, "fqe_steps"),
        fqe_refits: Optional[int] = from_field(OPESettings, "fqe_refits", given="{default}"),
        fqe_processes: Optional[int] = from_field(OPESettings, "fqe_processes"),
        workers: WorkersOption = None,
        ray_address: RayAddressOption = None,
        without: WithoutOption = None,
        without_episodes: WithoutEpisodesOption = None,
        html: Annotated[Optional[Path], typer.Option(
            "--html", help="Also write the cohort report to this HTML file (self-contained: "
                           "the verdict, a forest plot of every estimate with its interval or "
                           "why it is withheld, the log's support, where the decisions differ "
                           "from the logged actions, the residuals, and the steps to read, "
                           "each linked to its decision page).")] = None,
        pages: Annotated[Optional[Path], typer.Option(
            "--pages", help="Folder of the decision pages the report links (default: "
                            "REPORT-pages beside the report).")] = None,
        by: Annotated[Optional[str], typer.Option(
            "--by", help="The report's agreement by a tag of the held-out corpus, or by the "
                         "quartiles of an observation feature or numeric column.")] = None,
        top: Annotated[int, typer.Option(
            "--top", help="Steps the report lists, each with its decision page: where the "
                          "policy departs most from the logged action, then the thinnest "
                          "support.")] = 20,
        fmt: FormatOption = None,
    ) -> None:
        """Decide every logged step of a held-out corpus in batches and score the decisions
        (accuracy, AUC, calibration or value R^2; residuals; baselines on the same steps)."""
        fmt = resolve_format(fmt)
        with ProgressBar("evaluate", transient=True) as bar:
            summary = aoc_cli.evaluate(
                name, data, store=state.store, baselines=[b.strip() for b in baselines.split(",")],
                steps_file=steps_file, model=model, index_id=index_id, controller=controller,
                exact=exact, seed=seed, ope=ope_names,
                propensity=propensity, ope_gamma=ope_gamma,
                fqe_steps=fqe_steps, fqe_refits=fqe_refits, fqe_processes=fqe_processes,
                workers=workers,
                ray_address=ray_address,
                without=parse_selection(without, "--without"),
                without_episodes=parse_episodes(without_episodes), html=html, pages=pages,
                by=by, top=top, progress=bar)
        for text in summary.get("ope_warnings", []):
            warn(text)
        if html is not None:
            message(f"wrote {html}")
        write_evaluation(summary, fmt)
