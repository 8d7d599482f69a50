"""Diagnostic: how readable is pendulum-het's hidden system from each model's beliefs?

For each model of a corpus: the beliefs b(o, a, h) of every row (``row_beliefs``), a logistic
probe of the ``system`` tag fitted on rows of the model's training episodes and scored on rows
of its validation episodes, linear and quadratic (``logistic_probe(..., quadratic=True)``: the
system as an interaction, s = sign(a * s a)); the same probes on the raw (o, a) for reference.
docs/notes/belief.md reads the figures.

    python benchmarks/notes/belief_probe.py --store bench/store \\
        --corpus pendulum-het-upright-100000r-s0 --models default,dynamics,critic,reward
"""

from __future__ import annotations

import argparse
import json
import os

os.environ.setdefault("OMP_NUM_THREADS", "1")

from aoc_cli.threads import wait_passively  # noqa: E402

wait_passively()  # OpenMP threads wait passively, as under the aoc command (aoc_cli/threads.py)

import numpy as np  # noqa: E402

from aoc_cli.belief import episode_rows, load_model, logistic_probe, split_episodes  # noqa: E402
from aoc_cli.store import Store  # noqa: E402


def probes(features: np.ndarray, system: np.ndarray, tr: np.ndarray, va: np.ndarray) -> dict:
    """Linear and quadratic probe accuracy of ``system`` (N,) from ``features`` (N, d)."""
    return {kind: round(logistic_probe(features[tr], system[tr], features[va], system[va],
                                       quadratic=kind == "quadratic"), 3)
            for kind in ("linear", "quadratic")}


def main() -> None:
    p = argparse.ArgumentParser()
    p.add_argument("--store", default="bench/store")
    p.add_argument("--corpus", default="pendulum-het-upright-100000r-s0")
    p.add_argument("--models", default="default,dynamics,critic,reward")
    p.add_argument("--train-rows", type=int, default=20000)
    p.add_argument("--val-rows", type=int, default=10000)
    args = p.parse_args()
    corpus = Store.open(args.store).corpus(args.corpus)
    system = corpus.tag("system")[0]
    oa = np.concatenate([corpus.observations, corpus.actions], axis=1)
    for name in ["(o, a)", *args.models.split(",")]:
        model = None if name == "(o, a)" else load_model(corpus, name)
        config = model.config if model is not None else None
        seed = config.seed if config is not None else 0
        val_fraction = config.val_fraction if config is not None else 0.2
        train_eps, val_eps = split_episodes(corpus.n_episodes, val_fraction, seed)
        tr = episode_rows(corpus.episode_starts, train_eps)
        va = episode_rows(corpus.episode_starts, val_eps)
        rng = np.random.default_rng(0)  # the same rows for every model of one split
        tr = np.sort(rng.choice(tr, min(args.train_rows, len(tr)), replace=False))
        va = np.sort(rng.choice(va, min(args.val_rows, len(va)), replace=False))
        features = oa if model is None else model.row_beliefs(corpus)
        chance = float(max(system[va].mean(), 1 - system[va].mean()))
        print(json.dumps({"model": name,
                          "belief": None if model is None else model.config.belief,
                          "chance": round(chance, 3), **probes(features, system, tr, va)}),
              flush=True)


if __name__ == "__main__":
    main()
