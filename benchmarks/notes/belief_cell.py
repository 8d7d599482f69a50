"""Train one belief row's model of ``aoc bench`` by itself: the bench's corpus and the bench's
configuration (``aoc_cli.experiments.model_config`` at the scale), for one task and size.

``aoc bench pendulum-het --sizes N --methods aoc-critic`` trains a critic for each of the two
tasks' corpora (random and upright start); this trains the one asked for, so a single cell can
be measured on a shared machine, then indexed and rolled out with the CLI as the bench does:

    python benchmarks/notes/belief_cell.py --task pendulum-het-upright --rows 100000 --kind critic
    export AOC_STORE=bench/store C=pendulum-het-upright-100000r-s0
    aoc index $C --model critic
    aoc rollout $C --env pendulum-het-upright --model critic -n 8 --seed 10000

``--value``, ``--gamma``, ``--history-length``, ``--belief-dim``, ``--hidden``, ``--epochs``,
``--patience`` and ``--train-seed`` vary one setting of the bench's configuration (give
``--model`` a name of its own), e.g. the value belief on the return-to-go at gamma 0.9:

    python benchmarks/notes/belief_cell.py --task pendulum-het-upright --rows 100000 --kind value \
        --gamma 0.9 --model g09

Prints the training's progress reports (the critic's every 500 steps) and the final metrics as
JSON lines; the model is ``models/<kind>/`` of the corpus, where the bench looks for it.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
from dataclasses import replace

os.environ.setdefault("OMP_NUM_THREADS", "1")

from aoc_cli.threads import wait_passively  # noqa: E402

wait_passively()  # OpenMP threads wait passively, as under the aoc command (aoc_cli/threads.py)

from aoc_cli.belief import train_model  # noqa: E402
from aoc_cli.experiments import EXPERIMENTS, Artefacts, model_config  # noqa: E402

SCALES = {"pendulum-het": EXPERIMENTS["pendulum-het"].scales,
          "pendulum-het-upright": EXPERIMENTS["pendulum-het"].scales,
          "lunar": EXPERIMENTS["lunar"].scales}


def main() -> None:
    p = argparse.ArgumentParser()
    p.add_argument("--store", default="bench/store")
    p.add_argument("--task", default="pendulum-het-upright", choices=sorted(SCALES))
    p.add_argument("--rows", type=int, default=100_000)
    p.add_argument("--kind", default="critic", choices=("critic", "reward", "value"))
    p.add_argument("--scale", default="full", choices=("tiny", "quick", "full"))
    p.add_argument("--critic-steps", type=int, help="instead of the scale's")
    p.add_argument("--model", help="model id (default: the kind, as the bench names it; "
                   "the bench's value model is `default`)")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--train-seed", type=int, help="the model's seed, instead of --seed (the "
                   "corpus's)")
    p.add_argument("--value", help="the value target v (aoc train --value), instead of return")
    p.add_argument("--gamma", type=float, help="the return's discount, instead of 0.99")
    p.add_argument("--history-length", type=int, help="instead of 4")
    p.add_argument("--belief-dim", type=int, help="d_b, instead of 20")
    p.add_argument("--hidden", type=int, help="instead of 128")
    p.add_argument("--epochs", type=int, help="the most epochs, instead of the scale's")
    p.add_argument("--patience", type=int, help="instead of the scale's")
    args = p.parse_args()
    scale = dict(SCALES[args.task][args.scale])
    if args.critic_steps is not None:
        scale["critic_steps"] = args.critic_steps
    artefacts = Artefacts(args.store, log=lambda text: print(text, file=sys.stderr, flush=True))
    corpus = artefacts.corpus(args.task, rows=args.rows, seed=args.seed)
    if args.epochs is not None:
        scale["epochs"] = args.epochs
    if args.patience is not None:
        scale["patience"] = args.patience
    config = model_config(scale, args.kind,
                          args.seed if args.train_seed is None else args.train_seed)
    config = replace(config, **{name: getattr(args, name) for name in (
        "value", "gamma", "history_length", "belief_dim", "hidden")
        if getattr(args, name) is not None})

    def progress(done: int, total: int, label: str) -> None:
        """aoc_cli.progress's protocol: the epochs (or critic steps) done of the most."""
        print(json.dumps({"done": done, "total": total, "label": label}), flush=True)

    metrics = train_model(corpus, config, model_id=args.model or args.kind, overwrite=True,
                          progress=progress)
    print(json.dumps({"corpus": corpus.name, **metrics}), flush=True)


if __name__ == "__main__":
    main()
