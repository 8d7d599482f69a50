"""Rule 7 over denoised observations, on the cohort test bed: every observation, the log's and
the step's, first replaced by the mean of its nearest logged rows (each column over the rows
that measured it; the search over the cells both measured, in each column's near-row spread),
then every logged row within a radius of it in that denoised space read as its neighbourhood.
The same rule as rule 7 (the likely dose kept unless another's lower bound beats its own), the
rows valued by FQE over the same sets, rolled out on the same patients as the likely dose.

    python benchmarks/notes/cohort_denoised.py --stays 10000 --noise 0.3 \\
        [--radius 1.5,2,3,chi0.99,k150] [--smooth 20] [--episodes 20000] [--seed 0] \\
        [--rollout-seed 1]

The radius is c times the log's median squared distance to its 10th nearest row in the
denoised space; ``chi<q>`` (``chi0.99``) is what two denoised positions of one point differ
by instead: every column in the denoised rows' own near-row spread, the squared distance at
most 2 chi^2_d(q) (d the columns), read from the noise alone, not from how the rows gather;
``k<n>`` (``k150``) the n nearest, no radius; ``m<q>`` (``m0.99``) the chi-square quantile q of
two independent means of ``--smooth`` rows' noise, each column in the raw rows' near-row
spread (it ignores that a row's nearest rows are chosen by its own noise). A set holds at least 30 rows and at most 1,000.
One JSON line per radius: the sets' purity (the share of a row's set that shares its true
state), their median size, true survival and the paired difference from the likely dose (the
100 rows nearest over every cell, as in ``cohort_neighbourhoods.py``). Reads the table in
memory with its hidden state.
"""

from __future__ import annotations

import argparse
import json
import time

import numpy as np

# internal: the table, the near-row spread and the rule's pieces of the neighbourhood notes
import aoc_cli.envs.icu_cohort as cohort
from aoc_cli.index.search.neighbourhood import NEAREST, Neighbourhood, lower_bound_z
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
    from scipy.stats import chi2
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
        hood = Neighbourhood(t["x"], t["a"], t["episode"], N_ACTIONS, nearest=NEAREST)
        likely = cohort.rollout_value(lambda obs: hood.at(obs).likely, args.episodes,
                                      noise=args.noise, seed=seed)
        denoise, scale = denoiser(t, args.smooth)
        xd = denoise(t["x"], t["measured"])
        # each column's measured cells among a row's smooth nearest (the mean's count)
        held = np.maximum(args.smooth * t["measured"].mean(0), 1.0)
        spaces = {}

        def space(units: str):
            """(search(obs, measured), each logged row's nearest) in the denoised space, each
            column in ``units``: the raw rows' near-row spread, or the denoised rows' own."""
            if units not in spaces:
                sc = scale if units == "raw" else local_spread(xd)
                index = faiss.IndexFlatL2(xd.shape[1])
                index.add(np.ascontiguousarray(xd / sc, np.float32))

                def search(q, sc=sc, index=index):
                    return index.search(np.ascontiguousarray(q / sc, np.float32),
                                        min(CAP, len(xd)))
                spaces[units] = (lambda obs, measured, search=search: search(
                    denoise(np.asarray(obs, np.float64), measured)), search(xd))
            return spaces[units]
        for token in args.radius.split(","):
            started = time.perf_counter()
            chi, k = token.startswith("chi"), token.startswith("k")
            mean_of = token.startswith("m")
            search, near = space("own" if chi else "raw")
            radius = (2.0 * chi2.ppf(float(token[3:]), xd.shape[1]) if chi
                      else 2.0 * float(np.mean(1.0 / held)) * chi2.ppf(float(token[1:]),
                                                                     xd.shape[1]) if mean_of
                      else -1.0 if k else None)       # k<n>: the n nearest, no radius
            policy, purity = radius_rule(
                t, near, search, 0.0 if chi or k or mean_of else float(token), lower_bound_z(N_ACTIONS),
                int(token[1:]) if k else LEAST, radius=radius)
            out = cohort.rollout_value(policy, args.episodes, noise=args.noise, seed=seed)
            d = cohort.paired_difference(out["survived"], likely["survived"])
            print(json.dumps({
                "stays": args.stays, "noise": args.noise, "seed": args.seed,
                "rollout_seed": seed, "smooth": args.smooth, "radius": token,
                "purity": round(purity, 3), "median_size": policy.size,
                "value": round(out["value"], 4), "low": round(out["low"], 4),
                "high": round(out["high"], 4), "likely": round(likely["value"], 4),
                "minus_likely": [round(d[k], 4) for k in ("difference", "low", "high")],
                "seconds": round(time.perf_counter() - started, 1)}), flush=True)


if __name__ == "__main__":
    main()
