"""AOC on the cohort test bed (aoc_cli/envs/icu_cohort.py): a cohort CSV written from the
ICU-Sepsis MDP with noisy features, gaps and censored stays, ingested, trained and indexed
with no flag beyond the ingest's own (as docs/guide/clinical.md does), and AOC's true survival
measured by rolling it out in the same MDP through the same noise (20,000 episodes), beside
the clinicians' exact value, the clinicians' likely dose as rule 7 reads it (the same
patients: the paired difference) and the nearest-centre references. One JSON line per run.

    python benchmarks/notes/cohort_grid.py --stays 10000 --noise 0.3 --store /tmp/c \\
        [--seed 0] [--episodes 20000] [--threads 1] [--controller '{"do_no_harm": "off"}']

Each (stays, noise) cell of docs/results/icu-cohort.md is one run of this command.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

import aoc_cli
# internal: the test bed's vectorised rollout and the controller over many episodes at once
from aoc_cli.control.batch import BatchPolicy, LikelyPolicy
import aoc_cli.envs.icu_cohort as cohort
from aoc_cli.threads import thread_limits

ROOT = Path(__file__).resolve().parents[2]


def aoc(*args: str, store: Path) -> str:
    """One ``aoc`` command, as a user runs it; its stdout."""
    env = {**os.environ, "AOC_STORE": str(store)}
    cmd = [sys.executable, "-c", "from aoc_cli.cli.app import main; main()", *args]
    return subprocess.run(cmd, env=env, check=True, capture_output=True, text=True).stdout


def prepare(stays: int, noise: float, seed: int, store: Path, threads: int | None,
            train_args: list[str]) -> dict:
    """Write the CSV, ingest it, train and index: what a user runs. Returns the timings."""
    store.mkdir(parents=True, exist_ok=True)
    csv = store.parent / f"{store.name}-cohort.csv"
    subprocess.run([sys.executable, str(ROOT / "scripts" / "icu_cohort.py"), str(csv),
                    "--stays", str(stays), "--noise", str(noise), "--seed", str(seed)],
                   check=True, capture_output=True)
    aoc("ingest", str(csv), "--name", "c", "--discrete-actions", "--impute", "hold",
        "--outcome", "died_in_hosp", "--outcome-reward", "1=0,0=1", "--overwrite",
        store=store)
    started = time.perf_counter()
    extra = ["--threads", str(threads)] if threads else []
    trained = json.loads(aoc("train", "c", "--overwrite", "-f", "json", *extra, *train_args,
                             store=store))
    seconds = time.perf_counter() - started
    aoc("index", "c", store=store)
    return {"train_seconds": round(seconds, 1), "trained": trained}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--stays", type=int, default=10_000)
    ap.add_argument("--noise", type=float, default=0.3)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--episodes", type=int, default=20_000)
    ap.add_argument("--store", required=True)
    ap.add_argument("--threads", type=int, default=None)
    ap.add_argument("--reuse", action="store_true", help="decide with the model already there")
    ap.add_argument("--controller", default="{}", help="controller settings, JSON")
    ap.add_argument("--train-args", default="", help="more aoc train flags, one string")
    args = ap.parse_args()
    if args.threads:                     # the rollouts too, not only aoc train
        thread_limits(torch=args.threads, faiss=args.threads, blas=args.threads).__enter__()
    store = Path(args.store)
    info = {} if args.reuse else prepare(args.stays, args.noise, args.seed, store,
                                                  args.threads, args.train_args.split())
    session = aoc_cli.open_session("c", store=store, controller=json.loads(args.controller))
    ctl = session.controller
    started = time.perf_counter()
    kept = []
    policy = BatchPolicy(ctl)

    class Decide:
        reset = staticmethod(policy.reset)

        def __call__(self, obs, alive, measured):
            acts = policy(obs, alive, measured)
            likely = policy.last.get("likely")      # rule 7's, read by the decision itself
            kept.append(np.mean(acts == likely) if likely is not None else np.nan)
            return acts

    seed = args.seed + 1      # the same patients for every policy (common random numbers)
    aoc_value = cohort.rollout_value(Decide(), args.episodes, noise=args.noise, seed=seed)
    rolled = time.perf_counter() - started
    likely = cohort.rollout_value(LikelyPolicy(ctl), args.episodes, noise=args.noise, seed=seed)
    paired = cohort.paired_difference(aoc_value["survived"], likely["survived"])
    t = cohort.sepsis.tables("mean")
    near = {name: cohort.rollout_value(cohort.nearest_centre_policy(pol), args.episodes,
                                       noise=args.noise, seed=seed)["value"]
            for name, pol in (("clinicians_nearest", t.clinicians),
                              ("modal_nearest", t.modal()))}
    settings = (info.get("trained") or {}).get("metrics", {}).get("settings", {})
    print(json.dumps({
        "stays": args.stays, "noise": args.noise, "seed": args.seed,
        "episodes": args.episodes,
        "aoc": round(aoc_value["value"], 4), "low": round(aoc_value["low"], 4),
        "high": round(aoc_value["high"], 4), "clinicians": round(cohort.clinicians_value(), 4),
        "likely": round(likely["value"], 4),
        "aoc_minus_likely": [round(paired[k], 4) for k in ("difference", "low", "high")],
        **{k: round(v, 4) for k, v in near.items()},
        "kept_share": round(float(np.nanmean(kept)), 3) if kept else None,
        "do_no_harm": ctl.do_no_harm,
        "noise_measured": round(ctl.neighbourhood.noise, 4) if ctl.do_no_harm else None,
        "controller": {k: v for k, v in ctl.config.to_dict().items()
                       if k in ("epsilon", "residual_cap", "support_penalty", "do_no_harm",
                                "k")},
        "decided": [(r["setting"], r["value"]) for r in settings.get("decided", [])],
        "val_r2": ctl.model.meta["metrics"].get("val_r2"),
        "best_epoch": ctl.model.meta["metrics"].get("best_epoch"),
        "rule7_values": ctl.model.meta["metrics"].get("settings", {}).get("do_no_harm"),
        "train_seconds": info.get("train_seconds"),
        "rollout_seconds": round(rolled, 1)}))


if __name__ == "__main__":
    main()
