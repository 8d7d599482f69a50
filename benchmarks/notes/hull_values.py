"""Diagnostic: AOC with one model's beliefs and the hull values v^c of another value target.

The index of a value-mode model stores the values the model was trained on (``values.npy``),
so ``aoc train --gamma G`` changes both the belief and the hull's v^c. This rolls AOC out with
model ``--model``'s beliefs and index but v^c replaced, in memory, by ``--value``/``--gamma``
computed from the corpus (``aoc_cli.belief.targets.value_targets``), to tell which of the two
changes a result; the controller's settings are the task's, the episode seeds ``--seed``,
``--seed + 1``, ... as ``aoc rollout``'s.

    python benchmarks/notes/hull_values.py --corpus pendulum-het-upright-100000r-s0 --model g09 \\
        --value return --gamma 0.99 --env pendulum-het-upright -n 8 --seed 10000
"""

from __future__ import annotations

import argparse
import json
import os

os.environ.setdefault("OMP_NUM_THREADS", "1")

from aoc_cli.threads import wait_passively  # noqa: E402

wait_passively()  # OpenMP threads wait passively, as under the aoc command (aoc_cli/threads.py)

import numpy as np  # noqa: E402

from aoc_cli.belief import value_targets  # noqa: E402
from aoc_cli.control import open_session, run_episode  # noqa: E402
from aoc_cli.envs import make_env  # noqa: E402
from aoc_cli.store import DEFAULT_INDEX, DEFAULT_MODEL, Store  # noqa: E402


def main() -> None:
    p = argparse.ArgumentParser()
    p.add_argument("--store", default="bench/store")
    p.add_argument("--corpus", default="pendulum-het-upright-100000r-s0")
    p.add_argument("--model", default=DEFAULT_MODEL)
    p.add_argument("--value", default="return")
    p.add_argument("--gamma", type=float, default=0.99)
    p.add_argument("--env", default="pendulum-het-upright")
    p.add_argument("-n", "--episodes", type=int, default=8)
    p.add_argument("--seed", type=int, default=10000)
    args = p.parse_args()
    corpus = Store.open(args.store).corpus(args.corpus)
    session = open_session(corpus, args.model, DEFAULT_INDEX,
                           config=None, seed=args.seed)  # the model's own settings
    values = value_targets(corpus, args.value, args.gamma)
    session.index.values = values
    session.controller.value_std = float(np.std(values))
    env = make_env(args.env)
    returns = [run_episode(env, session.controller, session.history_length, corpus, e,
                           args.seed + e).total_return for e in range(args.episodes)]
    print(json.dumps({"model": args.model, "value": args.value, "gamma": args.gamma,
                      "returns": [round(r, 3) for r in returns],
                      "return_mean": float(np.mean(returns)),
                      "return_std": float(np.std(returns))}), flush=True)


if __name__ == "__main__":
    main()
