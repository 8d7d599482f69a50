"""Rule 7 over denoised observations, on the cohort test bed: every observation, the log's and
the step's, first replaced by the mean of its nearest logged rows (each column over the rows
that measured it; the search over the cells both measured, in each column's near-row spread),
then every logged row within a radius of it in that denoised space read as its neighbourhood.
The same rule as rule 7 (the likely dose kept unless another's lower bound beats its own), the
rows valued by FQE over the same sets, rolled out on the same patients as the likely dose.

    python benchmarks/notes/cohort_denoised.py --stays 10000 --noise 0.3 \\
        [--radius 1.5,2,3] [--smooth 20] [--episodes 20000] [--seed 0] [--rollout-seed 1]

The radius is c times the log's median squared distance to its 10th nearest row in the
denoised space; a set holds at least 30 rows and at most 1,000. One JSON line per radius: the sets'
purity (the share of a row's set that shares its true state), their median size, true
survival and the paired difference from the likely dose (the 100 rows nearest over every
cell, as in ``cohort_neighbourhoods.py``). Reads the table in memory with its hidden state.
"""

from __future__ import annotations

import argparse
import json
import time

import numpy as np

# internal: the table, the near-row spread and the rule's pieces of the neighbourhood notes
import aoc_cli.envs.icu_cohort as cohort
from aoc_cli.index.search.neighbourhood import Neighbourhood, lower_bound_z
from aoc_cli.threads import one_thread
from _cohort_sets import N_ACTIONS, local_spread, radius_rule, table    # this folder's

#: The rows of a set: at least, at most.
LEAST, CAP = 30, 1000


def denoiser(t: dict, smooth: int):
    """(denoise(obs (S, d), measured (S, d) or None) -> (S, d), scale (d,)): the mean of each
    observation's ``smooth`` nearest logged rows, each column over the rows that measured it."""
    x, m, n = t["x"], t["measured"], len(t["x"])
    scale = local_spread(x, m)
    raw = Neighbourhood(x, np.zeros(n, np.int64), np.zeros(n, np.int64), 1, nearest=smooth,
                        measured=m, scale=scale)

    def denoise(obs, measured):
        out = np.empty((len(obs), x.shape[1]))
        for a in range(0, len(obs), 8192):
            rows = raw.rows(np.asarray(obs[a:a + 8192], np.float64),
                            None if measured is None else measured[a:a + 8192])
            w = m[rows]                                                # (S, smooth, d)
            out[a:a + 8192] = np.where(w, x[rows], 0.0).sum(1) / np.maximum(w.sum(1), 1)
        return out
    return denoise, scale


def main() -> None:
    import faiss
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--stays", type=int, default=10_000)
    ap.add_argument("--noise", type=float, default=0.3)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--rollout-seed", type=int, default=None)
    ap.add_argument("--episodes", type=int, default=20_000)
    ap.add_argument("--radius", default="1.5,2,3")
    ap.add_argument("--smooth", type=int, default=20)
    args = ap.parse_args()
    t = table(args.stays, args.noise, args.seed)
    seed = args.seed + 1 if args.rollout_seed is None else args.rollout_seed
    with one_thread():
        hood = Neighbourhood(t["x"], t["a"], t["episode"], N_ACTIONS)
        likely = cohort.rollout_value(lambda obs: hood.at(obs).likely, args.episodes,
                                      noise=args.noise, seed=seed)
        denoise, scale = denoiser(t, args.smooth)
        index = faiss.IndexFlatL2(t["x"].shape[1])
        index.add(np.ascontiguousarray(denoise(t["x"], t["measured"]) / scale, np.float32))

        def search(q):
            return index.search(np.ascontiguousarray(q / scale, np.float32),
                                min(CAP, len(t["x"])))
        near = search(denoise(t["x"], t["measured"]))
        for c in (float(v) for v in args.radius.split(",")):
            started = time.perf_counter()
            policy, purity = radius_rule(t, near, lambda obs, measured: search(
                denoise(np.asarray(obs, np.float64), measured)), c,
                lower_bound_z(N_ACTIONS), LEAST)
            out = cohort.rollout_value(policy, args.episodes, noise=args.noise, seed=seed)
            d = cohort.paired_difference(out["survived"], likely["survived"])
            print(json.dumps({
                "stays": args.stays, "noise": args.noise, "seed": args.seed,
                "rollout_seed": seed, "smooth": args.smooth, "radius": c,
                "purity": round(purity, 3), "median_size": policy.size,
                "value": round(out["value"], 4), "low": round(out["low"], 4),
                "high": round(out["high"], 4), "likely": round(likely["value"], 4),
                "minus_likely": [round(d[k], 4) for k in ("difference", "low", "high")],
                "seconds": round(time.perf_counter() - started, 1)}), flush=True)


if __name__ == "__main__":
    main()
