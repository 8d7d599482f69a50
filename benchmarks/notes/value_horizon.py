"""Diagnostic: how much does each value target of a pendulum-het corpus say about the row's torque?

For each value target (the return-to-go at several gammas, the mean of the remaining rewards:
``aoc train --value return --gamma G`` / ``--value mean-return``), on the corpus's rows:

* ``policy_share`` / ``system_share``: the share of the target's variance explained by the
  behaviour policy / by the hidden system (the between-group variance over the total);
* ``action_r2`` per noisy controller: within that policy's rows, the squared correlation of the
  target with the squared error of the row's *effective* torque (s a, s = +1 normal, -1
  converse) against the noiseless controller's torque at the row's state
  (``aoc_cli.envs.pendulum_het.swingup_action``): how much of what the target varies by among a
  policy's rows is the quality of the row's own torque.

docs/notes/belief.md ("Upright at 100k") reads the figures:

    python benchmarks/notes/value_horizon.py --store bench/store --corpus pendulum-het-upright-100000r-s0
"""

from __future__ import annotations

import argparse
import json

import numpy as np

from aoc_cli.belief import discounted_return_to_go, mean_remaining_reward
from aoc_cli.envs import swingup_action
from aoc_cli.store import Store


def between_share(v: np.ndarray, groups: np.ndarray) -> float:
    """Share of var(v) (N,) explained by the group means of the (N,) int labels ``groups``."""
    means = np.zeros_like(v)
    for g in np.unique(groups):
        means[groups == g] = v[groups == g].mean()
    return float(means.var() / v.var())


def main() -> None:
    p = argparse.ArgumentParser()
    p.add_argument("--store", default="bench/store")
    p.add_argument("--corpus", default="pendulum-het-upright-100000r-s0")
    p.add_argument("--gammas", default="0.99,0.98,0.95,0.9,0.5")
    p.add_argument("--policies", default="swingup-noise0.5,swingup-noise1")
    args = p.parse_args()
    corpus = Store.open(args.store).corpus(args.corpus)
    rewards, starts = corpus.rewards, corpus.episode_starts
    sys_codes, sys_labels = corpus.tag("system")
    pol_codes, pol_labels = corpus.tag("policy")
    sign = np.where(sys_codes == sys_labels.index("normal"), 1.0, -1.0)
    expert = swingup_action(corpus.observations, "normal").reshape(-1)
    error = (sign * corpus.actions[:, 0] - expert) ** 2                      # (N,)
    targets = {f"return gamma {g}": discounted_return_to_go(rewards, starts, float(g))
               for g in args.gammas.split(",")}
    targets["mean-return"] = mean_remaining_reward(rewards, starts)
    for name, v in targets.items():
        out = {"target": name,
               "policy_share": round(between_share(v, pol_codes), 4),
               "system_share": round(between_share(v, sys_codes), 6)}
        for policy in args.policies.split(","):
            rows = pol_codes == pol_labels.index(policy)
            r = np.corrcoef(v[rows], error[rows])[0, 1]
            out[f"action_r2 {policy}"] = round(float(r ** 2), 3)
        print(json.dumps(out), flush=True)


if __name__ == "__main__":
    main()
