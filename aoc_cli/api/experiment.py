"""The API's bench entry: the paper's experiments end to end against the baselines
(:mod:`aoc_cli.experiments`), with their tables and plots written to a folder."""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path
from typing import Sequence

from aoc_cli.api.common import Log, StoreLike, open_store
from aoc_cli.control.config import ControllerLike, given_settings
from aoc_cli.errors import BadSetting, param
from aoc_cli.experiments import ORDER, expected_seconds, run_experiment
from aoc_cli.experiments.cohort import run_cohort
from aoc_cli.experiments.runner import SIZED, VARIED, check
from aoc_cli.experiments.sepsis import run_sepsis
from aoc_cli.experiments.ward import run_ward
from aoc_cli.progress import Progress, stage
from aoc_cli.store.paths import check_output

#: The columns of a rollout experiment's rows (ward and icu-sepsis have their own).
COLUMNS = ["experiment", "task", "method", "setting", "seeds", "return_mean",
           "return_mean_std", "success_rate", "upper_gate", "lower_gate", "ood_delay",
           "ood_flagged", "paper", "status"]
SCALES = ("full", "quick", "tiny")


@dataclass
class Benched:
    """One summary row per method (and setting) of the experiments run; ``columns``: the
    columns they are printed in (None: every key)."""

    experiment: str
    scale: str
    rows: list[dict]
    columns: list[str] | None


def bench(experiment: str, *, store: StoreLike = None, scale: str = "full",
          seeds: int | None = None, episodes: int | None = None,
          methods: Sequence[str] | None = None, out: str | os.PathLike | None = None,
          controller: ControllerLike = None, sizes: Sequence[int] | None = None, behaviour: str = "mix",
          bench_store: str | os.PathLike = "bench/store", workers: int | None = None,
          ray_address: str | None = None, source: str = "ward",
          noise: Sequence[float] | None = None, progress: Progress | None = None,
          log: Log | None = None) -> Benched:
    """Run ``experiment`` (pendulum-het, epsilon, k, maze-adapt, two-gates, lunar, ood, all,
    ward, icu-sepsis, icu-sepsis-terminate, icu-cohort) at ``scale`` (full, quick: <= 15 min
    each, tiny: seconds) with ``seeds`` seeds (ward: patient splits) and ``episodes`` per
    evaluation; ``methods``: a subset of the methods; ``controller``: AOC's controller settings
    (a ControllerConfig or a mapping of its fields; None: not given) over each experiment's own
    (the paper's; maze-adapt at epsilon 0.1) in the rollout experiments, each but the one an
    experiment varies; ``sizes``: rows per corpus (pendulum-het, lunar), episodes per log
    (icu-sepsis), stays per cohort (icu-cohort) or the patients of ward's log (one count);
    ``noise``: icu-cohort's feature noise sds (default: the scale's). Writes results.csv,
    summary.md, summary.json and plots to ``out`` (default bench/EXPERIMENT; ``all``:
    out/EXPERIMENT); corpora and models go to ``bench_store`` and are reused. ``source``:
    ward's log, ``ward`` (the simulated ward) or ``medkit`` (medkit-learn's ward simulator; the
    ``medkit`` extra). ``log``: the expected time, each experiment's outputs."""
    note = log or (lambda _text: None)
    if out is not None:
        check_output(out, "out", open_store(store).root, folder=True)
    if scale not in SCALES:
        raise BadSetting("scale", scale,
                         f"{param('scale')} {scale!r} is unknown: use {', '.join(SCALES)}")
    chosen = list(methods) if methods else None
    given = given_settings(controller)
    sizes = list(sizes) if sizes is not None else None
    bench_store = Path(bench_store)
    if source != "ward" and experiment != "ward":
        raise BadSetting("source", source, f"{param('source')} is ward's alone (the log it "
                         f"reads), not {experiment}'s")
    if noise is not None and experiment != "icu-cohort":
        raise BadSetting("noise", list(noise), f"{param('noise')} is icu-cohort's alone (its "
                         f"feature noise), not {experiment}'s")
    if experiment == "ward":  # imitation on a log: splits, not rollouts (experiments/ward.py)
        _no_controller(experiment, given)
        if seeds is not None and seeds < 1:
            raise BadSetting("seeds", seeds, f"{param('seeds')} (random patient splits) must be "
                             f">= 1, got {seeds}")
        if sizes is not None and (len(sizes) != 1 or sizes[0] < 22):
            raise BadSetting("sizes", sizes, f"{param('sizes')} for ward is one count of "
                             f"patients, at least 22 (two held out a split), got {sizes}")
        report = run_ward(Path(out) if out is not None else Path("bench/ward"), bench_store,
                          scale, seeds, log=note, progress=progress, source=source,
                          patients=sizes[0] if sizes is not None else None)
        note(f"ward ({source}): wrote {report['out']}/results.csv, summary.md, summary.json and ward.png "
             f"in {duration(report['seconds'])}")
        return Benched(experiment, scale, report["summary"], None)
    if experiment in ("icu-sepsis", "icu-sepsis-terminate"):  # exact values (sepsis.py)
        _no_controller(experiment, given)
        report = run_sepsis(Path(out) if out is not None else Path("bench") / experiment,
                            bench_store, scale, seeds, chosen, sizes, experiment, log=note,
                            progress=progress)
        note(f"{experiment}: wrote {report['out']}/results.csv, summary.md and summary.json in "
             f"{duration(report['seconds'])}")
        return Benched(experiment, scale, report["summary"], None)
    if experiment == "icu-cohort":  # true survival through the cohort's noise (cohort.py)
        _no_controller(experiment, given)
        report = run_cohort(Path(out) if out is not None else Path("bench") / experiment,
                            bench_store, scale, seeds, chosen, sizes,
                            list(noise) if noise is not None else None, episodes, log=note,
                            progress=progress)
        note(f"{experiment}: wrote {report['out']}/results.csv, summary.md and summary.json in "
             f"{duration(report['seconds'])}")
        return Benched(experiment, scale, report["summary"], None)
    check(experiment, scale, seeds, episodes, chosen, given, sizes,
          behaviour if experiment != "all" else "mix", workers)
    names = ORDER if experiment == "all" else [experiment]
    eta = expected_seconds(experiment, scale, seeds, episodes, chosen, sizes)
    note(f"aoc bench {experiment} ({scale}): expected time about {duration(eta)} on a 2-core "
         f"machine (less when the bench store at {bench_store} already holds the corpora and "
         "models)")
    records = []
    for i, name in enumerate(names):
        target = (Path(out) / name if out is not None else None) if experiment == "all" \
            else out
        label = f"bench {name}" + (f" ({i + 1}/{len(names)})" if len(names) > 1 else "")
        varied = VARIED.get(name)
        if varied in given:
            note(f"{name}: the {varied} given is ignored (it is what {name} varies)")
        report = run_experiment(name, scale, seeds, target, bench_store, episodes, chosen,
                                log=note, progress=stage(progress, label),
                                controller={k: v for k, v in given.items() if k != varied},
                                sizes=sizes,
                                behaviour=behaviour if name in SIZED else "mix",
                                workers=workers, address=ray_address)
        for rec in report["summary"]:
            if rec["status"] != "ok":
                note(f"{name}: {rec['method']} {rec['status']} ({rec['note']})")
        note(f"{name}: wrote {report['out']}/results.csv, summary.md, summary.json"
             f" and {len(report['plots'])} plots in {duration(report['seconds'])}")
        records += report["summary"]
    return Benched(experiment, scale, [{c: r.get(c) for c in COLUMNS} for r in records],
                   COLUMNS)


def _no_controller(experiment: str, given: dict) -> None:
    """ward, icu-sepsis and icu-cohort run their own controller: a setting given is an error."""
    if given:
        key = sorted(given)[0]
        raise BadSetting(key, given[key], f"{param(key)} applies to the rollout experiments, "
                         f"not to {experiment} (it runs its own settings)")


def duration(seconds: float) -> str:
    """``40 s``, ``12 min``, ``1.5 h``."""
    if seconds < 90:
        return f"{seconds:.0f} s"
    if seconds < 5400:
        return f"{seconds / 60:.0f} min"
    return f"{seconds / 3600:.1f} h"
