"""``aoc evaluate`` on the cohort test bed, over many held-out logs: is the verdict right or
"not shown" on every one, and where FQE is shown, does its interval cover AOC's true survival?

A model trained on one cohort (``cohort_grid.py --store STORE``, corpus ``c``) evaluates
``--logs`` held-out cohorts of ``--stays`` stays each (seeds 100, 101, ...; the same noise),
ingested as the clinical guide does (``--impute-like c``). The truth: AOC's survival rolled out
in the MDP over ``--truth-episodes`` episodes (its 95% interval), the clinicians' exact value.
A shown verdict is wrong when the true difference's interval lies on the other side of 0.
One JSON line per log, then a summary line.

    python benchmarks/notes/cohort_ope.py --store /tmp/c --noise 0.3 --logs 10 \\
        --stays 2000 [--truth-episodes 10000]
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
from pathlib import Path

import os

import numpy as np

import aoc_cli
# internal: the test bed's vectorised rollout and the controller over many episodes at once
from aoc_cli.control.batch import BatchPolicy
import aoc_cli.envs.icu_cohort as cohort

ROOT = Path(__file__).resolve().parents[2]


def aoc(*args: str, store: Path) -> str:
    """One ``aoc`` command, as a user runs it; its stdout."""
    env = {**os.environ, "AOC_STORE": str(store)}
    cmd = [sys.executable, "-c", "from aoc_cli.cli.app import main; main()", *args]
    return subprocess.run(cmd, env=env, check=True, capture_output=True, text=True).stdout


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--store", required=True)
    ap.add_argument("--noise", type=float, default=0.3)
    ap.add_argument("--logs", type=int, default=10)
    ap.add_argument("--stays", type=int, default=2000)
    ap.add_argument("--truth-episodes", type=int, default=10_000)
    args = ap.parse_args()
    store = Path(args.store)
    session = aoc_cli.open_session("c", store=store)
    truth = cohort.rollout_value(BatchPolicy(session.controller), args.truth_episodes,
                                 noise=args.noise, seed=7)
    clinicians = cohort.clinicians_value()
    diff = (truth["low"] - clinicians, truth["high"] - clinicians)
    rows = []
    for i in range(args.logs):
        csv = store.parent / f"{store.name}-held-{i}.csv"
        subprocess.run([sys.executable, str(ROOT / "scripts" / "icu_cohort.py"), str(csv),
                        "--stays", str(args.stays), "--noise", str(args.noise),
                        "--seed", str(100 + i)], check=True, capture_output=True)
        aoc("ingest", str(csv), "--name", f"h{i}", "--discrete-actions", "--impute-like", "c",
            "--outcome", "died_in_hosp", "--outcome-reward", "1=0,0=1", "--overwrite",
            store=store)
        out = json.loads(aoc("evaluate", "c", "--data", f"h{i}", "--baselines", "none",
                             "-f", "json", store=store))
        rec = out
        fqe = rec["policy_value"].get("fqe") or {}
        verdict = rec["verdict"]
        shown = verdict.endswith(": shown")
        wrong = shown and ((verdict.startswith("better") and diff[1] < 0)
                           or (verdict.startswith("worse") and diff[0] > 0))
        row = {"log": i, "verdict": verdict, "wrong": bool(wrong),
               "behaviour": rec.get("behaviour_value", {}).get("estimate"),
               "fqe": fqe.get("estimate"), "low": fqe.get("low"), "high": fqe.get("high"),
               "reason": fqe.get("reason"),
               "hardly_held": rec.get("support", {}).get("hardly_held"),
               "covers": None if fqe.get("estimate") is None
               else bool(fqe["low"] <= truth["value"] <= fqe["high"]),
               "error": None if fqe.get("estimate") is None
               else abs(fqe["estimate"] - truth["value"])}
        rows.append(row)
        print(json.dumps(row), flush=True)
    shown_fqe = [r for r in rows if r["fqe"] is not None]
    print(json.dumps({
        "noise": args.noise, "logs": args.logs, "stays": args.stays,
        "truth": {k: v for k, v in truth.items() if k != "survived"},
        "clinicians": clinicians,
        "wrong_verdicts": sum(r["wrong"] for r in rows),
        "shown_verdicts": sum(r["verdict"].endswith(": shown") for r in rows),
        "fqe_shown": len(shown_fqe),
        "fqe_covers": sum(r["covers"] for r in shown_fqe),
        "fqe_mean_abs_error": float(np.mean([r["error"] for r in shown_fqe]))
        if shown_fqe else None}))


if __name__ == "__main__":
    main()
