"""Value-mode `aoc evaluate` on an icu-sepsis log with the offline policy evaluation (issue 26):
held-out steps per second, decisions and OPE.

    OMP_NUM_THREADS=1 .venv/bin/python benchmarks/perf/evaluate_ope.py [--store DIR] [--repeats 3]
        [--per-step-episodes 1000] [-f json]

Uses the store of ``benchmarks/perf/ope_sepsis.py`` (run it first, or it builds the corpus of
10,000 clinician episodes, the paper-settings value model with no history and its index, and
a held-out log ``held0`` of 5,000 episodes). Times :func:`aoc_cli.control.evaluate.evaluate`
in this process (the model and index loaded once before; 25 candidate actions a step, the knn
and bc baselines), each case ``--repeats`` times, median reported, wall and CPU seconds
(user + system of this one-threaded process: what the wall figure would be on an idle core):

* ``per step``: every held-out step decided on its own (the path before deciding each distinct
  observation once), on the first ``--per-step-episodes`` episodes of the log (its rate per
  step does not depend on the log's size);
* ``distinct``: each distinct observation and history decided once, no OPE (``--ope none``);
* ``distinct + pdwis``: with PDWIS for the controller and both baselines;
* ``distinct + OPE``: with PDWIS, WDR and FQE (d3rlpy's DiscreteFQE network, the default
  steps: a fit and 10 refits per policy, all three policies' trained as one batched
  ensemble) for the controller and both baselines: ``aoc evaluate``'s default.
"""

from __future__ import annotations

import sys

import _harness as h
import numpy as np

from aoc_cli.control import ControllerConfig
from aoc_cli.control import evaluate as ev
from aoc_cli.control import open_session
from aoc_cli.control.ope_eval import OPESettings
from aoc_cli.errors import AocError
from aoc_cli.store import Store


def main() -> None:
    ap = h.parser(__doc__, repeats=3)
    ap.add_argument("--store", default="/tmp/aoc-ope-sepsis")
    ap.add_argument("--per-step-episodes", type=int, default=1000)
    args = ap.parse_args()
    store = Store(args.store)
    try:
        corpus, held = store.corpus("train"), store.corpus("held0")
    except AocError:
        sys.exit("run benchmarks/perf/ope_sepsis.py --logs 1 first (it builds the store)")
    # the paper's controller settings (not the task's), as this benchmark has always timed
    session = open_session(corpus, config=ControllerConfig())
    small_rows = int(held.episode_starts[args.per_step_episodes])
    first = f"held0-first{args.per_step_episodes}"  # the first episodes of held0
    try:
        few = store.corpus(first)
    except AocError:
        few = store.write(first, held.load().select_episodes(
            np.arange(held.n_episodes) < args.per_step_episodes))
    assert few.n_rows == small_rows
    none = OPESettings(estimators=())
    cases = {
        "per step": (few, none, True),
        "distinct": (held, none, False),
        "distinct + pdwis": (held, OPESettings(estimators=("pdwis",)), False),
        "distinct + OPE": (held, OPESettings(), False),
    }
    distinct = ev._value_distinct
    rows = []
    for name, (data, ope, per_step) in cases.items():
        def run(_i, data=data, ope=ope, per_step=per_step):
            if per_step:   # the path before: every step decided on its own
                ev._value_distinct = lambda ctx, *a: _per_step(ctx, *a)
                ev.chunk_size = lambda ctx, chunk_steps=ev.CHUNK_STEPS: chunk_steps
            try:
                return ev.evaluate(session, data, ["knn", "bc"], ope=ope)[0]
            finally:
                ev._value_distinct = distinct
                ev.chunk_size = _chunk_size

        runs = h.repeat(run, args.repeats)
        rows.append(h.row(name, data.n_rows, runs, unit="steps",
                          ope_s=float(np.median([o["ope_seconds"] for o in runs.outs])),
                          steps_per_cpu_s=data.n_rows / runs.cpu_median))
    h.emit(rows, args.format)


def _per_step(ctx, rows, ep, obs, hist, logged):
    out = ev._value(ctx, rows, ep, obs, hist, logged)
    if "knn" in ctx.baselines:
        out.baselines["knn"] = ctx.knn.predict(ctx, obs, logged, ep)
    return out


_chunk_size = ev.chunk_size

if __name__ == "__main__":
    main()
