"""`aoc bench EXPERIMENT`: the paper's experiments against the baselines, with tables and plots.
Parses and prints only; the work is in :func:`aoc_cli.api.bench`."""

from __future__ import annotations

from pathlib import Path
from typing import Optional

import typer

import aoc_cli
from aoc_cli.cli.common import (EpisodesOption, FormatOption, RayAddressOption, WorkersOption,
                                deciding, state)
from aoc_cli.errors import AocError
from aoc_cli.cli.output import ProgressBar, message, resolve_format, write_records


def register(app: typer.Typer) -> None:
    @app.command("bench")
    @deciding
    def bench_command(
        experiment: str = typer.Argument(
            ..., help="pendulum-het, epsilon, k, maze-adapt, two-gates, lunar, ood, all, "
                      "ward (ABC against BC, kNN and the majority on held-out patients), or "
                      "icu-sepsis, icu-sepsis-terminate (AOC against BC, kNN, CQL, BCQ on "
                      "clinicians' logs, valued exactly), icu-cohort (AOC against BC, CQL, "
                      "SPIBB told the state and the clinicians on noisy cohorts, by true "
                      "survival)."),
        quick: bool = typer.Option(False, "--quick", help="A reduced run (<= 15 min each)."),
        tiny: bool = typer.Option(False, "--tiny", help="A smoke-test run (seconds; no effect "
                                                        "to read from it)."),
        seeds: Optional[int] = typer.Option(None, "--seeds", help="Seeds (default: the scale's)."),
        episodes: EpisodesOption = None,
        methods: Optional[str] = typer.Option(None, "--methods",
                                              help="Comma-separated methods (default: all)."),
        out: Optional[Path] = typer.Option(None, "--out", help="Output folder (default "
                                           "bench/EXPERIMENT; with all: OUT/EXPERIMENT)."),
        controller: dict = None,
        sizes: Optional[str] = typer.Option(
            None, "--sizes", help="pendulum-het, lunar: comma-separated rows per corpus "
                                  "instead of the scale's (e.g. 100000, the paper's Low-Data); "
                                  "icu-sepsis: episodes per log (e.g. 1000,10000); "
                                  "icu-cohort: stays per cohort; ward: patients in its log "
                                  "(one count)."),
        noise: Optional[str] = typer.Option(
            None, "--noise", help="icu-cohort: comma-separated feature noise sds instead of "
                                  "the scale's (e.g. 0.3)."),
        behaviour: str = typer.Option(
            "mix", "--behaviour", help="pendulum-het, lunar: mix (the task's behaviour "
                                       "policies) or replay (an agent that starts random and "
                                       "improves, as the paper's replay buffers)."),
        bench_store: Path = typer.Option(Path("bench/store"), "--bench-store",
                                         help="Store for the bench's corpora and models."),
        source: str = typer.Option(
            "ward", "--source", help="ward: the log, ward (the simulated ward task) or medkit "
                                     "(medkit-learn's ward simulator, learned from real ward "
                                     "data as in the paper; pip install -e '.[medkit]')."),
        workers: WorkersOption = None,
        ray_address: RayAddressOption = None,
        fmt: FormatOption = None,
    ) -> None:
        """Run an experiment end to end; write results.csv, summary.md/json and PNGs."""
        fmt = resolve_format(fmt)
        if quick and tiny:
            raise AocError("give --quick or --tiny, not both")
        scale = "tiny" if tiny else "quick" if quick else "full"
        with ProgressBar(f"bench {experiment}") as bar:
            done = aoc_cli.bench(
                experiment, store=state.store, scale=scale, seeds=seeds, episodes=episodes,
                methods=[m.strip() for m in methods.split(",") if m.strip()] if methods else None,
                out=out, controller=controller, sizes=_sizes(sizes),
                behaviour=behaviour, bench_store=bench_store, workers=workers,
                ray_address=ray_address, source=source, noise=_noise(noise),
                progress=bar, log=message)
        write_records(done.rows, fmt, columns=done.columns,
                      title=f"aoc bench {experiment} ({scale})")


def _sizes(text: str | None) -> list[int] | None:
    """``--sizes 100000,300000`` -> [100000, 300000]; anything else is a one-line error."""
    if text is None:
        return None
    try:
        return [int(float(part)) for part in text.split(",") if part.strip()]
    except ValueError:
        raise AocError(f"--sizes must be comma-separated row counts, got {text!r}") from None


def _noise(text: str | None) -> list[float] | None:
    """``--noise 0,0.3`` -> [0.0, 0.3]; anything else is a one-line error."""
    if text is None:
        return None
    try:
        return [float(part) for part in text.split(",") if part.strip()]
    except ValueError:
        raise AocError(f"--noise must be comma-separated numbers, got {text!r}") from None
