"""Evaluate benchmark (issue 14): held-out steps scored per second by `aoc evaluate`, the whole
process (interpreter start, imports, loading, beliefs, decompositions, baselines, metrics).

    .venv/bin/python benchmarks/perf/evaluate.py [--patients 10000] [--repeats 3] [--store DIR]
                                            [--cases held,own,value,exact] [-f json]

Goal: at least 2,000 steps a second on a 100k-row corpus. Reported per case: steps per wall
second of the whole process (``per_s``), steps per CPU second (``steps_per_cpu_s``: user +
system time of the process, what the wall figure would be on an idle core, since evaluate runs
one thread) and inside evaluate() (``inside_per_s``: the summary's own seconds). Builds (once,
in ``--store``, through the API: ``aoc_cli.collect``, ``train``, ``build_index``) a ward
corpus of ``--patients`` stays (about 10 rows each), an imitation model (the paper's settings,
4 epochs: the speed does not depend on how well it is trained) with its index, and a value
model on the ``outcome`` column; a held-out ward log of a tenth as many patients. Then times,
``--repeats`` times each (median reported, and every run), the cases interleaved, in one
process per run:

* ``imitation, held out``: ``aoc evaluate ward100k --data held`` (knn and bc baselines);
* ``imitation, own``: ``aoc evaluate ward100k --data ward100k`` (every corpus step, its own
  episode left out), baselines on;
* ``imitation, own, exact``: the same with ``--exact`` (the index's exact search);
* ``value, held out``: ``aoc evaluate ward100k --model value --data held`` (the logged action's
  v_hat and the controller's choice over the 2 actions: 3 decompositions a step);
* ``held-per-action``, ``own-per-action``: the imitation cases with the nearest rows of each
  action (an index built with ``--neighbours per_action``, the default up to 20,000 rows).
"""

from __future__ import annotations

import json
import statistics
import sys
from pathlib import Path

import _harness as h

from aoc_cli.store import DEFAULT_MODEL


def build(store: Path, patients: int) -> None:
    """The corpora, models and indexes, each made (through the API) when missing."""
    h.corpus_ready(store, "held", "ward", episodes=patients // 10, seed=1)
    for model, settings in ((DEFAULT_MODEL, {"mode": "imitation"}),
                            ("value", {"value": "outcome"})):
        h.corpus_ready(store, "ward100k", "ward", episodes=patients, seed=0, model=model,
                       train=dict(paper=True, max_epochs=4, threads=1, **settings), index={})
    # the nearest rows of each action (the default up to 20,000 rows) instead of the
    # (d_b + 1) / the rarest share nearest rows (the default above)
    h.corpus_ready(store, "ward100k", index=dict(index_id="per-action",
                                                 neighbours="per_action"))


CASES = {
    "held": ("imitation, held out", ["ward100k", "--data", "held"]),
    "own": ("imitation, own", ["ward100k", "--data", "ward100k"]),
    "value": ("value, held out", ["ward100k", "--model", "value", "--data", "held"]),
    "exact": ("imitation, own, exact", ["ward100k", "--data", "ward100k", "--exact"]),
    "held-per-action": ("imitation, held out, per action",
                        ["ward100k", "--data", "held", "--index", "per-action"]),
    "own-per-action": ("imitation, own, per action",
                       ["ward100k", "--data", "ward100k", "--index", "per-action"]),
}


def main() -> None:
    ap = h.parser(__doc__, repeats=3)
    ap.add_argument("--patients", type=int, default=10_000)
    ap.add_argument("--store", type=Path, default=h.ROOT / "bench" / "evaluate-store")
    ap.add_argument("--cases", default="held,own,value,exact",
                    help="comma-separated: " + ", ".join(CASES)
                    + " (run interleaved, each --repeats times)")
    args = ap.parse_args()
    args.store.mkdir(parents=True, exist_ok=True)
    build(args.store, args.patients)
    chosen = {c.strip(): CASES[c.strip()] for c in args.cases.split(",")}
    print(f"load before: {h.load():.2f}", file=sys.stderr)
    runs = h.interleave({c: lambda _i, argv=argv: h.aoc(
        ["evaluate", *argv, "-f", "json"], store=args.store, env={"OMP_NUM_THREADS": "1"})
        for c, (_label, argv) in chosen.items()}, args.repeats)
    rows = []
    for c, (label, _argv) in chosen.items():
        summaries = [json.loads(out) for out in runs[c].outs]
        steps = summaries[0]["steps"]
        rows.append(h.row(label, steps, runs[c], unit="steps",
                          steps_per_cpu_s=statistics.median(steps / x for x in runs[c].cpu),
                          inside_per_s=statistics.median(steps / x["seconds"]
                                                         for x in summaries),
                          accuracy=summaries[0].get("accuracy"), auc=summaries[0].get("auc")))
    print(f"load after: {h.load():.2f}", file=sys.stderr)
    h.emit(rows, args.format)


if __name__ == "__main__":
    main()
