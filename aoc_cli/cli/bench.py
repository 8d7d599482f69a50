"""`aoc bench EXPERIMENT`: the paper's experiments against the baselines, with tables and plots."""

from __future__ import annotations

from pathlib import Path
from typing import Optional

import typer

from aoc_cli.cli.common import (EpisodesOption, EpsilonOption, FormatOption, RayAddressOption,
                               ResidualCapOption, WorkersOption)
from aoc_cli.errors import AocError
from aoc_cli.progress import stage
from aoc_cli.report import ProgressBar, message, resolve_format, write_records

COLUMNS = ["experiment", "task", "method", "setting", "seeds", "return_mean",
           "return_mean_std", "success_rate", "upper_gate", "lower_gate", "ood_delay",
           "ood_flagged", "paper", "status"]


def register(app: typer.Typer) -> None:
    @app.command("bench")
    def bench_command(
        experiment: str = typer.Argument(
            ..., help="pendulum-het, epsilon, k, maze-adapt, two-gates, lunar, ood, all, "
                      "ward (ABC against BC, kNN and the majority on held-out patients), or "
                      "icu-sepsis, icu-sepsis-terminate (AOC against BC, kNN, CQL, BCQ on "
                      "clinicians' logs, valued exactly)."),
        quick: bool = typer.Option(False, "--quick", help="A reduced run (<= 15 min each)."),
        tiny: bool = typer.Option(False, "--tiny", help="A smoke-test run (seconds; no effect "
                                                        "to read from it)."),
        seeds: Optional[int] = typer.Option(None, "--seeds", help="Seeds (default: the scale's)."),
        episodes: EpisodesOption = None,
        methods: Optional[str] = typer.Option(None, "--methods",
                                              help="Comma-separated methods (default: all)."),
        out: Optional[Path] = typer.Option(None, "--out", help="Output folder (default "
                                           "bench/EXPERIMENT; with all: OUT/EXPERIMENT)."),
        epsilon: EpsilonOption = None,
        residual_cap: ResidualCapOption = None,
        sizes: Optional[str] = typer.Option(
            None, "--sizes", help="pendulum-het, lunar: comma-separated rows per corpus "
                                  "instead of the scale's (e.g. 100000, the paper's Low-Data); "
                                  "icu-sepsis: episodes per log (e.g. 1000,10000)."),
        behaviour: str = typer.Option(
            "mix", "--behaviour", help="pendulum-het, lunar: mix (the task's behaviour "
                                       "policies) or replay (an agent that starts random and "
                                       "improves, as the paper's replay buffers)."),
        bench_store: Path = typer.Option(Path("bench/store"), "--bench-store",
                                         help="Store for the bench's corpora and models."),
        workers: WorkersOption = None,
        ray_address: RayAddressOption = None,
        fmt: FormatOption = None,
    ) -> None:
        """Run an experiment end to end; write results.csv, summary.md/json and PNGs."""
        from aoc_cli.experiments import ORDER, expected_seconds, run_experiment
        from aoc_cli.experiments.runner import SIZED, check

        fmt = resolve_format(fmt)
        if out is not None:
            from aoc_cli.cli.common import get_store
            from aoc_cli.store.paths import check_output

            check_output(out, "--out", get_store().root, folder=True)
        if quick and tiny:
            raise AocError("give --quick or --tiny, not both")
        scale = "tiny" if tiny else "quick" if quick else "full"
        if experiment == "ward":  # imitation on a log: splits, not rollouts (experiments/ward.py)
            _ward(out, bench_store, scale, seeds, fmt)
            return
        if experiment in ("icu-sepsis", "icu-sepsis-terminate"):  # exact values (bench/sepsis.py)
            _sepsis(experiment, out, bench_store, scale, seeds, methods, sizes, fmt)
            return
        chosen = [m.strip() for m in methods.split(",") if m.strip()] if methods else None
        row_counts = _sizes(sizes)
        check(experiment, scale, seeds, episodes, chosen, epsilon, residual_cap, row_counts,
              behaviour if experiment != "all" else "mix", workers)
        names = ORDER if experiment == "all" else [experiment]
        eta = expected_seconds(experiment, scale, seeds, episodes, chosen, row_counts)
        message(f"aoc bench {experiment} ({scale}): expected time about "
                f"{_duration(eta)} on a 2-core machine (less when the bench store at "
                f"{bench_store} already holds the corpora and models)")
        records = []
        with ProgressBar(f"bench {experiment}") as bar:
            for i, name in enumerate(names):
                target = (out / name if out is not None else None) if experiment == "all" \
                    else out
                label = f"bench {name}" + (f" ({i + 1}/{len(names)})" if len(names) > 1 else "")
                if epsilon is not None and name in ("epsilon", "two-gates"):
                    message(f"{name}: --epsilon ignored (epsilon is what it varies)")
                report = run_experiment(name, scale, seeds, target, bench_store, episodes,
                                        chosen, log=message, progress=stage(bar, label),
                                        epsilon=None if name in ("epsilon", "two-gates")
                                        else epsilon, residual_cap=residual_cap,
                                        sizes=row_counts,
                                        behaviour=behaviour if name in SIZED else "mix",
                                        workers=workers, address=ray_address)
                for rec in report["summary"]:
                    if rec["status"] != "ok":
                        message(f"{name}: {rec['method']} {rec['status']} ({rec['note']})")
                message(f"{name}: wrote {report['out']}/results.csv, summary.md, summary.json"
                        f" and {len(report['plots'])} plots in {_duration(report['seconds'])}")
                records += report["summary"]
        rows = [{c: r.get(c) for c in COLUMNS} for r in records]
        write_records(rows, fmt, columns=COLUMNS, title=f"aoc bench {experiment} ({scale})")


def _ward(out, bench_store, scale, splits, fmt) -> None:
    from aoc_cli.experiments.ward import run_ward

    if splits is not None and splits < 1:
        raise AocError(f"--seeds (random patient splits) must be >= 1, got {splits}")
    with ProgressBar("bench ward") as bar:
        report = run_ward(out or Path("bench/ward"), bench_store, scale, splits, log=message,
                          progress=bar)
    message(f"ward: wrote {report['out']}/results.csv, summary.md, summary.json and ward.png "
            f"in {_duration(report['seconds'])}")
    write_records(report["summary"], fmt, title=f"aoc bench ward ({scale})")


def _sepsis(task, out, bench_store, scale, seeds, methods, sizes, fmt) -> None:
    from aoc_cli.experiments.sepsis import run_sepsis

    chosen = [m.strip() for m in methods.split(",") if m.strip()] if methods else None
    with ProgressBar(f"bench {task}") as bar:
        report = run_sepsis(out or Path("bench") / task, bench_store, scale, seeds, chosen,
                            _sizes(sizes), task, log=message, progress=bar)
    message(f"{task}: wrote {report['out']}/results.csv, summary.md and summary.json in "
            f"{_duration(report['seconds'])}")
    write_records(report["summary"], fmt, title=f"aoc bench {task} ({scale})")


def _sizes(text: str | None) -> list[int] | None:
    """``--sizes 100000,300000`` -> [100000, 300000]; anything else is a one-line error."""
    if text is None:
        return None
    try:
        return [int(float(part)) for part in text.split(",") if part.strip()]
    except ValueError:
        raise AocError(f"--sizes must be comma-separated row counts, got {text!r}") from None


def _duration(seconds: float) -> str:
    if seconds < 90:
        return f"{seconds:.0f} s"
    if seconds < 5400:
        return f"{seconds / 60:.0f} min"
    return f"{seconds / 3600:.1f} h"
