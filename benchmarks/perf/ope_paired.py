"""``aoc evaluate``'s offline policy evaluation on a 5,000-episode icu-sepsis log, two checkouts
of aoc paired: is the new one's OPE slower than the old one's? (issue 36, item 7: FQE in plain
torch against its hand-written backpropagation and Adam)

    OMP_NUM_THREADS=1 .venv/bin/python benchmarks/perf/ope_paired.py --old DIR [--new DIR]
        [--also DIR] [--rounds 5] [--no-warm-up] [--store DIR] [--held-episodes 5000]
        [-f json]

``--old`` / ``--new``: the roots of two checkouts (``--new`` defaults to this one's), e.g. the
old from ``git archive 3832a90 | tar -x -C /tmp/old``; ``--also``: a third, timed in the same
rounds and compared with the old one too. The store (``--store``) is
benchmarks/perf/ope_sepsis.py's (built here with this checkout when missing): the corpus
``train`` of 10,000 clinician episodes with its model and index, and ``held0``, 5,000 held-out
episodes (seed 1000). Each run is a fresh process with one checkout first on ``PYTHONPATH``:
it opens the session as ``aoc evaluate`` does (:func:`aoc_cli.open_session`, the task's
settings) and times :func:`aoc_cli.evaluation.score.score_log` of ``held0`` with the knn and bc
baselines and the default OPE (PDWIS, WDR, FQE with its 10 refits for AOC and both baselines,
and the behaviour's FQE), as a later ``aoc evaluate`` of the log runs it (each checkout's
held-out targets kept by an untimed first run; ``--no-warm-up`` where an earlier run of the
same checkouts kept them). Wall and CPU seconds (this process's and its
forked FQE parts'), and the OPE's own seconds (the summary's ``ope_seconds``). The rounds
interleave the two (old first in even rounds, new first in odd ones), so that the shared
machine's load hits both alike (with ``--also``: old, new, also, rotated); printed: each
side's medians and the median of the rounds' new / old (and also / old) ratios, with the load
average at each round.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import _harness as h

h.omp_threads(1)

#: The child: one evaluate of held0 with the default OPE, timed (its checkout on the path).
CHILD = r"""
import json, os, sys, time
store_dir, held = sys.argv[1], sys.argv[2]
import aoc_cli
from aoc_cli.evaluation import score as ev
try:
    from aoc_cli.ope.evaluate_block import OPESettings
except ImportError:  # a checkout from before ope/policies.py was renamed
    from aoc_cli.ope.policies import OPESettings
from aoc_cli.store import Store
from aoc_cli.threads import one_thread
store = Store(store_dir)
session = aoc_cli.open_session("train", store=store)
data = store.corpus(held)
t0, c0 = time.perf_counter(), os.times()
with one_thread():
    summary = getattr(ev, "score_log", None) or ev.evaluate  # before the rename: evaluate
    summary = summary(session, data, ["knn", "bc"], ope=OPESettings())[0]
wall, c1 = time.perf_counter() - t0, os.times()
cpu = sum(c1[:4]) - sum(c0[:4])
pick = lambda rec: ((rec or {}).get("policy_value") or {}).get("fqe")
fqe = {"aoc": pick(summary), **{k: pick(v) for k, v in summary["baselines"].items()}}
print(json.dumps({"wall": wall, "cpu": cpu, "ope_seconds": summary.get("ope_seconds"),
                  "file": aoc_cli.__file__, "fqe": fqe}, default=float))
"""


def run(tree: Path, store: str, held: str) -> dict:
    env = {**os.environ, "PYTHONPATH": str(tree), "OMP_NUM_THREADS": "1"}
    out = subprocess.run([sys.executable, "-c", CHILD, store, held], env=env, cwd=str(tree),
                         capture_output=True, text=True, check=False)
    if out.returncode:
        raise SystemExit(f"the run of {tree} failed:\n{out.stderr[-3000:]}")
    rec = json.loads(out.stdout.strip().splitlines()[-1])
    if not rec["file"].startswith(str(tree)):
        raise SystemExit(f"{tree}'s run imported {rec['file']}")
    return rec


def main() -> None:
    import numpy as np
    import ope_sepsis

    from aoc_cli.store import Store

    ap = h.parser(__doc__)
    ap.add_argument("--old", required=True, help="root of the old checkout")
    ap.add_argument("--new", default=str(h.ROOT), help="root of the new checkout (this one)")
    ap.add_argument("--also", default=None, help="root of a third checkout")
    ap.add_argument("--rounds", type=int, default=5)
    ap.add_argument("--no-warm-up", action="store_true",
                    help="no untimed first run (the store keeps each side's targets already)")
    ap.add_argument("--store", default="/tmp/aoc-evaluate-sepsis")
    ap.add_argument("--held-episodes", type=int, default=5000)
    args = ap.parse_args()
    store = Store(args.store)
    ope_sepsis.prepare(store, 10_000)
    held = "held0" if args.held_episodes == 5000 else f"held0-{args.held_episodes}"
    h.corpus_ready(store, held, "icu-sepsis", episodes=args.held_episodes, seed=1000)
    trees = {"old": Path(args.old).resolve(), "new": Path(args.new).resolve()}
    if args.also:
        trees["also"] = Path(args.also).resolve()
    for side, tree in trees.items() if not args.no_warm_up else ():   # untimed: targets kept
        print(f"warm-up {side}: {run(tree, args.store, held)['wall']:.1f} s", file=sys.stderr)
    runs: dict = {side: [] for side in trees}
    sides = list(trees)
    for r in range(args.rounds):
        order = sides[r % len(sides):] + sides[:r % len(sides)]
        load = os.getloadavg()[0]
        for side in order:
            runs[side].append({**run(trees[side], args.store, held), "load": load})
            print(f"round {r} {side}: {runs[side][-1]['wall']:.1f} s wall, "
                  f"{runs[side][-1]['cpu']:.1f} s CPU, load {load:.1f}", file=sys.stderr)
    med = lambda side, key: float(np.median([o[key] for o in runs[side]]))
    ratio = lambda side, key: float(np.median([n[key] / o[key]
                                               for n, o in zip(runs[side], runs["old"])]))
    rows = [{"case": side, "rounds": args.rounds, "wall_s": round(med(side, "wall"), 2),
             "cpu_s": round(med(side, "cpu"), 2),
             "ope_s": round(med(side, "ope_seconds"), 2),
             "loads": [round(o["load"], 1) for o in runs[side]],
             "fqe": runs[side][-1]["fqe"]} for side in sides]
    rows += [{"case": f"{side} / old (median of the rounds' ratios)", "rounds": args.rounds,
              "wall_s": round(ratio(side, "wall"), 3), "cpu_s": round(ratio(side, "cpu"), 3),
              "ope_s": round(ratio(side, "ope_seconds"), 3)} for side in sides[1:]]
    if args.format == "json":
        print(json.dumps(rows, indent=1, default=float))
    else:
        for row in rows:
            print(" | ".join(f"{k} {v}" for k, v in row.items()))


if __name__ == "__main__":
    main()
