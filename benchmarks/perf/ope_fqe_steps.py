"""How many gradient steps FQE needs on icu-sepsis's held-out logs (docs/notes/results-ope.md, "icu-sepsis:
offline policy evaluation"): ``aoc evaluate``'s direct method (``ope_fqe.fqe_policies``: the
fit, 10 warm-started refits, cosine learning rate, bagged estimate) of AOC, BC and the
clinicians at each ``--steps`` count, per log, for a choice by convergence.

    OMP_NUM_THREADS=1 .venv/bin/python benchmarks/perf/ope_fqe_steps.py --store DIR \
        --logs 0,1,2,3,4 --steps 5300,10600,21200 [--target-update 100] [--lr 1e-3] [--hidden 64,64] --out runs.json

``--store`` is one ``benchmarks/perf/ope_sepsis.py`` has built (its ``train`` corpus, model
and index, and held-out logs ``held0``, ``held1``, ...; AOC's and BC's policies as that script
makes them). Each line: log, steps, each policy's bagged estimate and one fit's, the log's mean
return, CPU seconds. The exact values are recorded in the output for the record; the choice
reads only the estimates (how far each moves when the steps double) and the clinicians'
estimate against the log's mean return (the behaviour's value, estimated without bias).
"""

from __future__ import annotations

import functools
import json
import time
from pathlib import Path

import _harness as h

h.omp_threads(1)

import numpy as np  # noqa: E402
import ope_sepsis as O  # noqa: E402

from aoc_cli.envs.icu_sepsis import tables  # noqa: E402
from aoc_cli.ope import fqe as ope_fqe  # noqa: E402
from aoc_cli.store import Store  # noqa: E402
from aoc_cli.threads import one_thread  # noqa: E402


def main() -> None:
    ap = h.parser(__doc__, rows=False)
    ap.add_argument("--store", required=True)
    ap.add_argument("--logs", default="0,1,2,3,4")
    ap.add_argument("--steps", default="5300,10600,21200")
    ap.add_argument("--target-update", type=int, default=None,
                    help="steps between target syncs (default: ope_fqe.TARGET_UPDATE)")
    ap.add_argument("--lr", type=float, default=None,
                    help="FQE's learning rate (default: ope_fqe.LEARNING_RATE)")
    ap.add_argument("--hidden", default=None,
                    help="FQE's hidden layers, e.g. 32,32 (default: ope_fqe.HIDDEN)")
    ap.add_argument("--out", default=None)
    args = ap.parse_args()
    fit_args = {k: v for k, v in (("target_update", args.target_update),
                                  ("learning_rate", args.lr)) if v}
    if fit_args:               # fqe_policies builds its FQEFit from the module's name
        ope_fqe.FQEFit = functools.partial(ope_fqe.FQEFit, **fit_args)
    if args.hidden:            # FQEFit reads the module's HIDDEN when it builds the network
        ope_fqe.HIDDEN = tuple(int(u) for u in args.hidden.split(","))
    store = Store(args.store)
    t = tables("mean")
    corpus = store.corpus("train")
    pols = {"aoc": O.aoc_policy(store, corpus, t), "bc": O.bc_policy(corpus, t)}
    truth = {k: t.mdp.value(p) for k, p in pols.items()}
    truth["clinicians"] = t.mdp.value(t.clinicians)
    runs = []
    for i in [int(x) for x in args.logs.split(",")]:
        held = store.corpus(f"held{i}")
        s = held.column("state").astype(np.int64)
        n = held.n_actions
        probs = {"aoc": np.eye(n)[pols["aoc"][s]], "bc": np.eye(n)[pols["bc"][s]],
                 "clinicians": t.clinicians[s]}
        starts = np.asarray(held.episode_starts)
        mean_return = float(np.asarray(held.rewards).sum() / (len(starts) - 1))
        for steps in [int(x) for x in args.steps.split(",")]:
            cpu = time.process_time()
            with one_thread():
                recs = ope_fqe.fqe_policies(held.observations, np.asarray(held.actions, np.int64),
                                            held.rewards, starts, list(probs.values()), 1.0,
                                            steps=steps)
            run = {"log": i, "steps": steps, "target_update": args.target_update or ope_fqe.TARGET_UPDATE,
                   "lr": args.lr or ope_fqe.LEARNING_RATE, "hidden": list(ope_fqe.HIDDEN), "mean_return": mean_return,
                   "cpu": time.process_time() - cpu,
                   **{k: {"estimate": r["estimate"], "fit": r["fit_estimate"], "low": r["low"],
                          "high": r["high"]} for k, r in zip(probs, recs)}}
            runs.append(run)
            print(json.dumps({"log": i, "steps": steps, "U": run["target_update"], "lr": run["lr"], "hidden": run["hidden"], "cpu": round(run["cpu"]),
                              **{k: round(run[k]["estimate"], 4) for k in probs},
                              "mean_return": round(mean_return, 4)}), flush=True)
            if args.out:
                Path(args.out).write_text(json.dumps({"truth": truth, "runs": runs}, indent=1))


if __name__ == "__main__":
    main()
