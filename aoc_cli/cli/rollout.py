"""`aoc rollout NAME --env ENV`: run the controller (or a baseline) in an environment.
Parses and prints only; the work is in :func:`aoc_cli.api.rollout`."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated, Optional

import typer

import aoc_cli
from aoc_cli.cli.common import (CorpusArgument, EpisodesOption, ExcludeOption, FormatOption,
                                IndexOption, ModelOption, PolicyName, PolicyOption, SelectOption,
                                choice, deciding, parse_selection, state)
from aoc_cli.cli.output import (ProgressBar, message, resolve_format, write_object,
                            write_records)
from aoc_cli.store import DEFAULT_INDEX


def register(app: typer.Typer) -> None:
    @app.command("rollout")
    @deciding
    def rollout_command(
        name: CorpusArgument,
        env: Annotated[str, typer.Option(
            "--env", help="A built-in task (aoc collect --list) or a gymnasium id.")],
        episodes: EpisodesOption = 5,
        policy: PolicyOption = PolicyName.aoc,
        model: ModelOption = None,
        index_id: IndexOption = DEFAULT_INDEX,
        controller: dict = None,
        select: SelectOption = None,
        exclude: ExcludeOption = None,
        seed: Annotated[int, typer.Option(
            "--seed", help="Seed of the first episode and of the candidates.")] = 0,
        audit: Annotated[Optional[Path], typer.Option(
            "--audit", help="Write every decision to this HDF5 file.")] = None,
        plot: Annotated[Optional[Path], typer.Option(
            "--plot", help="Write a PNG of trajectories or residual/reward curves.")] = None,
        noise_after: Annotated[Optional[int], typer.Option(
            "--noise-after", help="Disturb actions after this step (OOD test).")] = None,
        noise_std: Annotated[float, typer.Option(
            "--noise-std", help="Disturbance std as a fraction of the action range.")] = 0.5,
        ood_reference: Annotated[Optional[Path], typer.Option(
            "--ood-reference", help="Audit log of clean rollouts: flag steps against its "
                                    "per-step 3-sigma band instead of the running one.")] = None,
        fmt: FormatOption = None,
    ) -> None:
        """Run episodes; print returns, success, OOD flags and residuals."""
        fmt = resolve_format(fmt)
        with ProgressBar("rollout", episodes) as p:
            done = aoc_cli.rollout(
                name, env, store=state.store, episodes=episodes, policy=choice(policy),
                model=model, index_id=index_id, controller=controller,
                select=parse_selection(select, "--select"),
                exclude=parse_selection(exclude, "--exclude"), seed=seed, audit=audit,
                plot=plot, noise_after=noise_after, noise_std=noise_std,
                ood_reference=ood_reference, progress=p)
        if plot is not None:
            message(f"wrote {plot}")
        if audit is not None:
            message(f"wrote the audit log {audit}")
        _print(done.results, done.summary, fmt, f"{done.policy} on {env} ({done.corpus})")


def _print(results, summary: dict, fmt: str, title: str) -> None:
    rows = [r.summary() for r in results]
    if fmt == "json":
        write_object({"episodes": rows, "summary": summary}, "json")
    elif fmt == "table":
        write_records(rows, "table", title=title)
        write_object(summary, "table", title="summary")
    else:
        write_records(rows, fmt)
        message("summary: " + ", ".join(f"{k}={v}" for k, v in summary.items()))
