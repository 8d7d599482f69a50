"""Do the intervals that ``aoc evaluate`` shows cover, with the propensities estimated as a
user's log needs them and with the true ones (issue 36)? One table: icu-sepsis, held-out logs
of clinician episodes, AOC, BC and the clinicians.

    OMP_NUM_THREADS=1 .venv/bin/python benchmarks/perf/ope_coverage.py --processes 10 \\
        [--logs 10] [--episodes 5000] [--policies policies.npz] [--store DIR] [--out runs.json]

The policies: AOC's decision in every state and BC's (the training log's modal action per
state), from ``--policies`` (an ``.npz`` with arrays ``aoc`` and ``bc``, (716,) each, that
``--save-policies`` writes) or computed as benchmarks/perf/ope_sepsis.py does (a 10,000
episode training corpus, its value model and index as ``aoc train``/``aoc index`` build them
with no flags, AOC with the task's controller settings: needs faiss and d3rlpy); the
clinicians are the behaviour itself. Truths: the package's tables by a linear solve. Each of
``--logs`` held-out logs (seeds 1000, 1001, ...) of ``--episodes`` episodes is evaluated in
its own process (``--processes`` at once, one thread each), by ``aoc evaluate``'s library
path (:func:`aoc_cli.ope.value.policy_value`: PDWIS and WDR withheld where the log does not
support them, FQE with its refits, the improvement over the logged behaviour and its paired
interval), once with the log's true ``propensity`` column and once with the propensities
estimated (:func:`aoc_cli.ope.propensity.fit_propensities`, as for a log without the
column). FQE does not use the propensities: one FQE per log serves both.

Prints one row per policy, propensities and estimator: on how many logs it is shown, how many
of those intervals cover the truth, its mean |error| and width there, whether it meets the
goal (coverage >= 8 of 10 of the shown, mean |error| <= 0.015), and, for PDWIS and WDR, the
same over every log before the rule (what withholding removed); then the improvement
V(policy) - V(clinicians): coverage of the exact difference by the shown estimators' paired
intervals, and the verdicts.
"""

from __future__ import annotations

import json
import sys
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import _harness as h

h.omp_threads(1)

import numpy as np  # noqa: E402

POLICIES = ("aoc", "bc", "clinicians")
ESTIMATORS = ("pdwis", "wdr", "fqe")


def compute_policies(store_dir: str, train_episodes: int) -> dict:
    """AOC's and BC's (716,) state policies as benchmarks/perf/ope_sepsis.py computes them."""
    import ope_sepsis  # lazy: needs faiss and the training corpus (the bench's preparation)

    from aoc_cli.envs.icu_sepsis import tables
    from aoc_cli.store import Store

    store = Store(store_dir)
    t = tables("mean")
    corpus = ope_sepsis.prepare(store, train_episodes)
    return {"aoc": ope_sepsis.aoc_policy(store, corpus, t), "bc": ope_sepsis.bc_policy(corpus, t)}


def run_log(i: int, episodes: int, policies: dict, settings: dict, n_boot: int) -> list[dict]:
    """Every policy's OPE on held-out log ``i`` (seed 1000 + i), with true and estimated
    propensities: one record per (propensities, policy)."""
    from aoc_cli.envs.icu_sepsis import collect_data, tables
    from aoc_cli.ope import estimators as ope
    from aoc_cli.ope.evaluate_block import OPESettings, truncated
    from aoc_cli.ope.propensity import fit_propensities
    from aoc_cli.ope.support import fqe_refusal
    from aoc_cli.ope.value import fqe_values, policy_value
    from aoc_cli.threads import one_thread

    started = time.perf_counter()
    t = tables("mean")
    data, _ = collect_data(episodes=episodes, seed=1000 + i)
    s = data.columns["state"].astype(np.int64)
    logged = np.asarray(data.actions, np.int64)
    rows = np.arange(len(logged))
    log = ope.Log(data.episode_starts, data.rewards, 1.0, truncated(data))
    n = t.clinicians.shape[1]
    probs = {"aoc": np.eye(n)[policies["aoc"][s]], "bc": np.eye(n)[policies["bc"][s]],
             "clinicians": t.clinicians[s]}
    truth = {"aoc": t.mdp.value(np.eye(n)[policies["aoc"]]),
             "bc": t.mdp.value(np.eye(n)[policies["bc"]]), "clinicians": t.mdp.value(t.clinicians)}
    opts = OPESettings(n_boot=n_boot, **settings)
    out = []
    with one_thread():
        fit = fit_propensities(data.observations, logged, data.episode_starts, n, seed=0)
        props = {"true": data.columns["propensity"], "estimated": fit["probs"][rows, logged]}
        # WDR's Q cross-fitted where either propensities' ESS lets the rule show it
        fqes = fqe_values(log, data.observations, logged, list(probs.values()), opts,
                          behaviour=True, propensity=list(props.values()))
        own = fqes.pop() if len(fqes) > len(probs) else None   # aoc evaluate's FQE check
        mean = ope.bootstrap(log, {"m": ("mean", log.returns())}, n_boot=n_boot,
                             seed=opts.seed)["m"]
        off = None if own is None else fqe_refusal(own["estimate"], mean.low, mean.high)
        for rec in fqes:
            if off is not None and rec is not None:
                rec["withheld"] = off
        for kind, prop in props.items():
            for (name, pol), fqe in zip(probs.items(), fqes):
                rec = policy_value(log, data.observations, logged, prop, pol, n, opts, fqe=fqe)
                rho = ope.ratios(pol[rows, logged], prop)
                specs = {"pdwis": ("pdwis", rho)}
                if fqe is not None and fqe.get("q") is not None:
                    q = fqe.get("q_cross", fqe["q"])
                    specs["wdr"] = ("wdr", rho, q[rows, logged], (pol * q).sum(1))
                raw = ope.bootstrap(log, specs, n_boot=n_boot, seed=opts.seed)  # before the rule
                out.append({"log": i, "propensities": kind, "policy": name,
                            "truth": truth[name], "truth_gain": truth[name] - truth["clinicians"],
                            "ess": rec["ess"], "reached": rec["support"]["reached"],
                            "first_step_weight": rec["support"]["first_step_weight"],
                            "policy_value": rec["policy_value"], "improvement": rec["improvement"],
                            "verdict": rec["verdict"], "mean_return": mean.estimate,
                            "behaviour_fqe": None if own is None else own["estimate"],
                            "raw": {k: v.as_dict() for k, v in raw.items()},
                            "propensity_log_loss": fit["log_loss"] if kind == "estimated" else None,
                            "propensity_ece": fit["ece"] if kind == "estimated" else None})
    for r in out:
        r["seconds"] = time.perf_counter() - started
    return out


def _summary(entries: list, truths: list) -> tuple:
    """(shown, covered, mean |error|, mean width) of estimate dicts against their truths."""
    shown = [(e, t) for e, t in zip(entries, truths) if e and e.get("estimate") is not None]
    if not shown:
        return 0, 0, None, None
    err = [abs(e["estimate"] - t) for e, t in shown]
    cover = sum(e["low"] <= t <= e["high"] for e, t in shown)
    width = [e["high"] - e["low"] for e, _ in shown]
    return len(shown), cover, float(np.mean(err)), float(np.mean(width))


def table(runs: list) -> list[dict]:
    """One row per policy, propensities and estimator (module docstring)."""
    rows = []
    for name in POLICIES:
        for kind in ("estimated", "true"):
            rs = [r for r in runs if r["policy"] == name and r["propensities"] == kind]
            if not rs:
                continue
            for est in ESTIMATORS:
                if not any(est in r["policy_value"] for r in rs):
                    continue                            # not run (--estimators)
                truths = [r["truth"] for r in rs]
                n, cover, err, width = _summary([r["policy_value"].get(est) for r in rs], truths)
                gn, gcover, gerr, _ = _summary([r["improvement"].get(est) for r in rs],
                                               [r["truth_gain"] for r in rs])
                meets = None if n == 0 else bool(cover >= 0.8 * n and err <= 0.015)
                row = {"policy": name, "truth": round(rs[0]["truth"], 4), "propensities": kind,
                       "estimator": est, "shown": f"{n} of {len(rs)}",
                       "covers": f"{cover} of {n}" if n else "-",
                       "mean_abs_error": None if err is None else round(err, 4),
                       "width": None if width is None else round(width, 3),
                       "meets_goal": "-" if meets is None else ("yes" if meets else "NO"),
                       "gain_covers": f"{gcover} of {gn}" if gn else "-"}
                if est != "fqe":
                    rn, rcover, rerr, _ = _summary([r["raw"].get(est) for r in rs], truths)
                    row["before_rule"] = (f"{rcover} of {rn}, |err| {rerr:.4f}" if rn else "-")
                row["ess"] = round(float(np.mean([r["ess"] for r in rs])), 1)
                rows.append(row)
    return rows


def markdown(rows: list) -> str:
    cols = list(dict.fromkeys(k for r in rows for k in r))
    out = ["| " + " | ".join(cols) + " |", "|" + "---|" * len(cols)]
    for r in rows:
        out.append("| " + " | ".join("" if r.get(c) is None else str(r.get(c)) for c in cols)
                   + " |")
    return "\n".join(out)


def main() -> None:
    ap = h.parser(__doc__, rows=False)
    ap.add_argument("--logs", type=int, default=10)
    ap.add_argument("--first", type=int, default=0)
    ap.add_argument("--episodes", type=int, default=5000)
    ap.add_argument("--processes", type=int, default=1,
                    help="logs evaluated at once, each in its own process with one thread")
    ap.add_argument("--policies", default=None, help=".npz with aoc and bc (716,) policies")
    ap.add_argument("--save-policies", default=None, help="write the policies here and stop")
    ap.add_argument("--store", default="/tmp/aoc-ope-sepsis")
    ap.add_argument("--train-episodes", type=int, default=10000)
    ap.add_argument("--fqe-steps", type=int, default=None)
    ap.add_argument("--fqe-refits", type=int, default=10)
    ap.add_argument("--n-boot", type=int, default=1000)
    ap.add_argument("--estimators", default="pdwis,wdr,fqe",
                    help="as aoc evaluate's --ope (pdwis alone: no FQE, the quick table)")
    ap.add_argument("--out", default=None, help="every record, JSON")
    ap.add_argument("--table", default=None, metavar="JSON",
                    help="only print the table of a run's --out records")
    args = ap.parse_args()
    if args.table:
        runs = json.loads(Path(args.table).read_text())
        print(markdown(table(runs)))
        verdicts(runs, sorted({r["log"] for r in runs})[0])
        return
    if args.policies:
        with np.load(args.policies) as z:
            policies = {k: z[k].astype(np.int64) for k in ("aoc", "bc")}
    else:
        policies = compute_policies(args.store, args.train_episodes)
    if args.save_policies:
        np.savez(args.save_policies, **policies)
        print(f"policies written to {args.save_policies}", file=sys.stderr)
        return
    settings = {"fqe_steps": args.fqe_steps, "fqe_refits": args.fqe_refits,
                "fqe_processes": 1,
                "estimators": tuple(x for x in args.estimators.split(",") if x)}
    started = time.perf_counter()
    logs = range(args.first, args.first + args.logs)
    runs = []
    with ProcessPoolExecutor(max_workers=max(1, args.processes)) as pool:
        jobs = [pool.submit(run_log, i, args.episodes, policies, settings, args.n_boot)
                for i in logs]
        for job in jobs:
            got = job.result()
            runs += got
            print(f"log {got[0]['log']}: {got[0]['seconds']:.0f} s", file=sys.stderr)
            if args.out:
                Path(args.out).write_text(json.dumps(runs, indent=1))
    print(f"{len(logs)} logs of {args.episodes} episodes in "
          f"{time.perf_counter() - started:.0f} s ({args.processes} processes)", file=sys.stderr)
    print(markdown(table(runs)))
    verdicts(runs, args.first)


def verdicts(runs: list, first: int) -> None:
    """How often each policy's verdict says "shown", and the first log's verdict."""
    print()
    for name in POLICIES:
        for kind in ("estimated", "true"):
            v = [r["verdict"] for r in runs if r["policy"] == name and r["propensities"] == kind]
            if not v:
                continue
            shown = sum(x.endswith(": shown") for x in v)
            gain = next(r["truth_gain"] for r in runs if r["policy"] == name)
            print(f"{name}, {kind} propensities: verdict 'shown' on {shown} of {len(v)} logs "
                  f"(true difference {gain:+.4f}); log {first}: {v[0]}")


if __name__ == "__main__":
    main()
