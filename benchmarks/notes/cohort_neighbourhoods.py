"""What rule 7's neighbourhoods cost against the state itself, on the cohort test bed: the same
rule (the lower bound of each dose's mean neighbourhood value, the clinicians' likely dose kept
unless another's bound beats its own) over different sets of rows, every policy rolled out on
the same patients (common random numbers), paired against the likely dose of the 100 rows
nearest over every cell (rule 7's before its distance left the held cells out).

    python benchmarks/notes/cohort_neighbourhoods.py --stays 10000 --noise 0.3 \\
        [--episodes 20000] [--variants rule7,state,state100,m300,denoised] [--z 1.645] \\
        [--prior 5] [--seed 0] [--rollout-seed 1]

Variants (the rows a decision reads; each row valued by FQE over its own sets of rows):

* ``rule7``: the 100 rows nearest over the cells both measured (rule 7 before its sets were
  the rows near the denoised observation, ``cohort_denoised.py``);
  ``plain``: over every cell, held or measured (rule 7 before); ``m<k>``: the k nearest so;
* ``denoised``: the 100 nearest after every observation is replaced by the mean of its 10
  nearest logged rows;
* ``state``: every row of the true state (read through the nearest cluster centre): rule 2
  told the state, an upper reference; ``state100``: 100 of them at random;
* ``nearsv``: rule 7's rows, each valued by FQE over the true states; ``statenv``: the
  state's rows, each valued by FQE over the neighbourhoods (which one rule 7 loses: values or
  sets);
* ``kmeans<k>``: the observation's group of k by k-means of the standardised features;
* ``masked<c>``: every row (30 to 1,000) within c times the log's median squared distance to
  its 10th nearest row, over the cells both measured, in the table's own units;
  ``maskedsd<c>``: over the features standardised as rule 7's;
* ``rule7raw``: rule 7's rows in the table's own units; ``rule7local``: in each column's
  spread among near rows (``local_spread``, about the noise where the rows are a state's);
  ``local<k>``: the k nearest so; ``radius<c>``: ``masked<c>`` so.

``--z``: the bound's z in place of z_K (2.878 for 25 doses), every variant's. ``--prior P``:
each dose's own spread in the bound in place of the log's pooled one, shrunk toward it with the
weight of P rows (sqrt((D + P sigma^2) / (n - 1 + P)), D its rows' squared deviations about
their mean value, n its rows), in the variants over the nearest rows and over the state.

One JSON line per variant: the neighbourhoods' purity (the share of a row's set that shares its
true state), true survival and the paired difference from the likely dose; for the variants
told the state (``state``, ``state100``, ``statenv``) also ``exact``, the policy's survival
solved exactly in the MDP (it decides by state), free of the rollouts' error. Reads the table in
memory (``cohort_table``) with its hidden state; the store and the CLI play no part.
"""

from __future__ import annotations

import argparse
import json
import re
import time

import numpy as np

# internal: the table's hidden state, the vectorised rollout, rule 7's neighbourhoods and FQE
import aoc_cli.envs.icu_cohort as cohort
import aoc_cli.envs.icu_sepsis as sepsis
from aoc_cli.index.search.masked import MaskedIndex
from aoc_cli.index.search.neighbourhood import NEAREST, Neighbourhood, lower_bound_z
from aoc_cli.index.search.neighbourhood import neighbourhood_values
from aoc_cli.threads import one_thread
from _cohort_sets import N_ACTIONS, kept_or_best, local_spread, radius_rule  # this folder's
from _cohort_sets import successor, table                                   # this folder's

N_STATES = 716
#: The bound's z (``--z``; None: z_K of the 25 doses).
Z = None
#: The weight in rows of the pooled spread in each dose's own (``--prior``; None: pooled).
PRIOR = None


def bound_z() -> float:
    return lower_bound_z(N_ACTIONS) if Z is None else Z


def spread(dev: np.ndarray, rows: np.ndarray, sigma: float) -> np.ndarray | float:
    """Each dose's sd in the bound: the pooled ``sigma``, or with ``--prior`` its own,
    shrunk toward sigma; dev, rows (S, K) its squared deviations and rows."""
    if PRIOR is None:
        return sigma
    return np.sqrt((dev + PRIOR * sigma ** 2) / (np.maximum(rows - 1, 0) + PRIOR))


def near_bounds(hood: Neighbourhood, near) -> np.ndarray:
    """(S, K) rule 7's bounds over a neighbourhood, each dose's spread as ``--prior`` says."""
    if PRIOR is None:
        return hood.bounds(near)
    s, acts, vals = len(near.rows), hood.actions[near.rows], hood.values[near.rows]
    at = (np.repeat(np.arange(s), near.rows.shape[1]), acts.ravel())
    rows, dev = np.zeros((s, N_ACTIONS)), np.zeros((s, N_ACTIONS))
    np.add.at(rows, at, 1)
    centre = np.nan_to_num(near.mean)[np.arange(s)[:, None], acts]
    np.add.at(dev, at, ((vals - centre) ** 2).ravel())
    with np.errstate(divide="ignore"):
        half = bound_z() * spread(dev, rows, hood.noise) / np.sqrt(near.episodes)
    return np.where(near.episodes > 0, np.nan_to_num(near.mean, nan=-np.inf) - half, -np.inf)


def near_rule(t: dict, nearest: int, smooth: int | None, state_valued: bool = False,
              masked: bool = False, scale: np.ndarray | None = None):
    """(policy, purity) of rule 7 over ``nearest`` rows, the observations first averaged over
    their ``smooth`` nearest logged rows where given; with ``state_valued`` each row valued by
    FQE over the true states instead of over the neighbourhoods; with ``masked`` the distance
    over the cells both rows measured (the policy reads the step's measured cells)."""
    x = t["x"]
    own = t["measured"] if masked else None
    denoise = None
    if smooth:
        raw = Neighbourhood(x, t["a"], t["episode"], N_ACTIONS, nearest=smooth)

        def denoise(obs):
            return x[raw.rows(np.asarray(obs, np.float64).reshape(len(obs), -1))].mean(1)
        x = denoise(x)
    y, info = neighbourhood_values(x, t["r"], t["starts"], 1.0, censored=t["censored"],
                                   nearest=nearest, measured=own, scale=scale)
    purity = float((t["state"][info["rows"].array()] == t["state"][:, None]).mean())
    if state_valued:
        y = state_values(t)
    hood = Neighbourhood(x, t["a"], t["episode"], N_ACTIONS, values=y, nearest=nearest,
                         measured=own, scale=scale)
    hood.z = bound_z()
    if masked:
        class Policy:
            def reset(self, episodes):
                pass

            def __call__(self, obs, alive, measured):
                near = hood.at(obs, measured)
                return kept_or_best(near_bounds(hood, near), near.likely)
        return Policy(), purity

    def policy(obs):
        near = hood.at(denoise(obs) if denoise else obs)
        return kept_or_best(near_bounds(hood, near), near.likely)
    return policy, purity


def state_values(t: dict) -> np.ndarray:
    """(N,) each row's value by FQE over the true states (the mean over a state's rows)."""
    s, r = t["state"], t["r"]
    n = len(s)
    nxt, going = successor(t)
    y = np.zeros(n)
    count = np.maximum(np.bincount(s, minlength=N_STATES), 1)
    for _ in range(2000):
        v = np.bincount(s, weights=y, minlength=N_STATES) / count
        new = r + np.where(going, v[s[nxt]], 0.0)
        done = np.abs(new - y).max() < 1e-6
        y = new
        if done:
            break
    return y


def kmeans_rule(t: dict, k: int, seed: int = 0):
    """(policy, purity) of the rule over k-means groups of the standardised features (faiss,
    k groups): a row's set is its group, an observation's the group of its nearest centroid;
    rows valued by FQE over the neighbourhoods."""
    import faiss
    x = t["x"]
    mu, sd = x.mean(0), x.std(0)
    z = np.ascontiguousarray((x - mu) / np.where(sd > 1e-12, sd, 1.0), dtype=np.float32)
    km = faiss.Kmeans(z.shape[1], k, niter=25, seed=seed, max_points_per_centroid=10_000)
    km.train(z)
    _, label = km.index.search(z, 1)
    label = label[:, 0].astype(np.int64)
    # purity: the share of a row's group that shares its true state
    pair = label * N_STATES + t["state"]
    per = np.bincount(pair, minlength=k * N_STATES)[pair]
    purity = float(np.mean(per / np.bincount(label, minlength=k)[label]))
    y, _ = neighbourhood_values(x, t["r"], t["starts"], 1.0, censored=t["censored"])
    groups = {**t, "state": label}

    def assign(obs):
        q = np.ascontiguousarray((np.asarray(obs, np.float64) - mu) / np.where(
            sd > 1e-12, sd, 1.0), dtype=np.float32)
        return km.index.search(q, 1)[1][:, 0].astype(np.int64)
    policy, _ = state_rule(groups, None, values=y, n_groups=k, assign=assign)
    return policy, purity


def masked_rule(t: dict, c: float, standardise: bool = False, least: int = 30,
                cap: int = 1000, local: bool = False):
    """(policy, purity) of the rule over the rows within the masked radius (``masked<c>``,
    ``maskedsd<c>`` with ``standardise``); the policy reads the cells the environment measured
    at the step."""
    x = t["x"]
    scale = (x.std(0) if standardise else local_spread(x, t["measured"]) if local
             else np.ones(x.shape[1]))
    scale = np.where(scale > 1e-12, scale, 1.0)
    index = MaskedIndex(x / scale, t["measured"], candidates=2 * cap)
    cap = min(cap, len(x))

    def search(q, qm):
        return index.search(np.asarray(q, np.float64) / scale, qm, cap)
    return radius_rule(t, search(x, t["measured"]), search, c, bound_z(), least)


def state_rule(t: dict, cap: int | None, seed: int = 0, values: np.ndarray | None = None,
               n_groups: int = N_STATES, assign=None):
    """(policy, purity 1) of the same rule over the rows of the true state (``cap`` of them
    at random where given), each valued by FQE over the states (or by ``values``)."""
    s, a, ep = t["state"], t["a"], t["episode"]
    n = len(s)
    y = state_values(t) if values is None else values
    keep = np.ones(n, bool)
    if cap:
        order = np.lexsort((np.random.default_rng(seed).random(n), s))
        first = np.r_[0, np.cumsum(np.bincount(s, minlength=n_groups))[:-1]]
        rank = np.empty(n, np.int64)
        rank[order] = np.arange(n) - first[s[order]]
        keep = rank < cap
    g = (s * N_ACTIONS + a)[keep]
    size = n_groups * N_ACTIONS
    rows = np.bincount(g, minlength=size)
    mean = np.divide(np.bincount(g, weights=y[keep], minlength=size), rows,
                     out=np.full(size, -np.inf), where=rows > 0)
    dev = np.bincount(g, weights=(y[keep] - np.where(rows[g] > 0, mean[g], 0.0)) ** 2,
                      minlength=size)
    sigma = np.sqrt(dev.sum() / np.maximum(rows - 1, 0).sum())
    pairs = np.unique(g * (ep.max() + 1) + ep[keep])
    episodes = np.bincount(pairs // (ep.max() + 1), minlength=size)
    with np.errstate(divide="ignore", invalid="ignore"):
        low = np.where(episodes > 0, mean - bound_z() * spread(dev, rows, sigma) /
                       np.sqrt(episodes), -np.inf).reshape(n_groups, N_ACTIONS)
    likely = rows.reshape(n_groups, N_ACTIONS).argmax(1)

    def policy(obs):
        st = cohort.nearest_state(obs) if assign is None else assign(obs)
        return kept_or_best(low[st], likely[st])
    if assign is None:        # it decides by state: its survival solved exactly
        policy.states = kept_or_best(low, likely)
    return policy, 1.0


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--stays", type=int, default=10_000)
    ap.add_argument("--noise", type=float, default=0.3)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--episodes", type=int, default=20_000)
    ap.add_argument("--variants", default="rule7,state,state100,m300,denoised")
    ap.add_argument("--z", type=float, default=None, help="the bound's z (default z_K)")
    ap.add_argument("--rollout-seed", type=int, default=None,
                    help="the patients' seed (default: the log's seed + 1)")
    ap.add_argument("--prior", type=float, default=None,
                    help="each dose's own spread, shrunk toward the pooled (weight in rows)")
    args = ap.parse_args()
    global Z, PRIOR
    Z, PRIOR = args.z, args.prior
    t = table(args.stays, args.noise, args.seed)
    local = lambda: local_spread(t["x"], t["measured"])           # noqa: E731
    build = {"rule7": lambda: near_rule(t, 100, None, masked=True),
             "rule7raw": lambda: near_rule(t, 100, None, masked=True,
                                           scale=np.ones(t["x"].shape[1])),
             "rule7local": lambda: near_rule(t, 100, None, masked=True, scale=local()),
             "plain": lambda: near_rule(t, 100, None), "denoised": lambda: near_rule(t, 100, 10),
             "state": lambda: state_rule(t, None), "state100": lambda: state_rule(t, 100),
             "nearsv": lambda: near_rule(t, 100, None, state_valued=True),
             "statenv": lambda: state_rule(t, None, values=neighbourhood_values(
                 t["x"], t["r"], t["starts"], 1.0, censored=t["censored"])[0])}
    patterns = ((r"m(\d+)", lambda k: near_rule(t, int(k), None)),
                (r"local(\d+)", lambda k: near_rule(t, int(k), None, masked=True,
                                                    scale=local())),
                (r"kmeans(\d+)", lambda k: kmeans_rule(t, int(k))),
                (r"maskedsd([\d.]+)", lambda c: masked_rule(t, float(c), standardise=True)),
                (r"masked([\d.]+)", lambda c: masked_rule(t, float(c))),
                (r"radius([\d.]+)", lambda c: masked_rule(t, float(c), local=True)))
    names = args.variants.split(",")
    for name in names:            # checked before any work
        for pattern, make in patterns:
            hit = name not in build and re.fullmatch(pattern, name)
            if hit:
                build[name] = lambda make=make, arg=hit.group(1): make(arg)
        if name not in build:
            raise SystemExit(f"unknown variant {name!r}: one of {', '.join(build)}, "
                             "m<k> (the k nearest), kmeans<k> (k groups), "
                             "masked<c>, maskedsd<c> (the masked radius), local<k>, "
                             "radius<c> (over the near rows' spread)")
    hood = Neighbourhood(t["x"], t["a"], t["episode"], N_ACTIONS, nearest=NEAREST)
    seed = args.seed + 1 if args.rollout_seed is None else args.rollout_seed
    with one_thread():
        likely = cohort.rollout_value(lambda obs: hood.at(obs).likely, args.episodes,
                                      noise=args.noise, seed=seed)
        for name in names:
            started = time.perf_counter()
            policy, purity = build[name]()
            out = cohort.rollout_value(policy, args.episodes, noise=args.noise, seed=seed)
            d = cohort.paired_difference(out["survived"], likely["survived"])
            exact = getattr(policy, "states", None)
            print(json.dumps({
                "stays": args.stays, "noise": args.noise, "seed": args.seed, "variant": name,
                "z": round(bound_z(), 3), "prior": PRIOR,
                **({} if exact is None else {"exact": round(
                    sepsis.tables().mdp.value(exact.astype(np.int64)), 4)}),
                "purity": round(purity, 3), "value": round(out["value"], 4),
                "low": round(out["low"], 4), "high": round(out["high"], 4),
                "likely": round(likely["value"], 4),
                "minus_likely": [round(d[k], 4) for k in ("difference", "low", "high")],
                "seconds": round(time.perf_counter() - started, 1)}), flush=True)


if __name__ == "__main__":
    main()
