"""What choosing the settings by cross-validation costs ``aoc train`` on a ward-sized log
(docs/notes/benchmarks-rounds.md, "Settings chosen by cross-validation").

    OMP_NUM_THREADS=1 .venv/bin/python benchmarks/perf/select_cost.py [--split 0]
        [--folds 1,3] [--rules auc] [--repeats 3] [--log-seed 0] [-f json]

``aoc bench ward``'s patient split ``--split`` of the ward log (550 patients; its training
side, 500 patients, ~5,000 rows), the model trained as the bench trains it (``train_corpus``:
the settings left open chosen by validation, one thread), with the selection's folds set to
each of ``--folds`` (1: one validation split, the rule before; 3: the default now), the fold
counts interleaved round by round, and with each of ``--rules``: ``auc`` (the rule now:
the lowest log-loss among the candidates within 0.01 of the best held-out ABC AUC, each
candidate's fold decomposed and scored) or ``loss`` (the rule before: the log-loss alone, no
fold decomposed; the final model's own validation of ABC still runs). One row per case: the
median wall and CPU seconds of the whole training, the search's own median seconds, what each
run chose, and the ratio to the first case (median of the rounds' ratios).
"""

from __future__ import annotations

import tempfile
from pathlib import Path

import _harness as h
import numpy as np

from aoc_cli.training import tuning
from aoc_cli.training.fit import train_corpus
from aoc_cli.envs import collect
from aoc_cli.store import Store

PATIENTS = 550


def main() -> None:
    ap = h.parser(__doc__, repeats=3)
    ap.add_argument("--split", type=int, default=0)
    ap.add_argument("--folds", default="1,3")
    ap.add_argument("--log-seed", type=int, default=0)
    ap.add_argument("--rules", default="auc", help="auc, loss or both (comma-separated)")
    args = ap.parse_args()
    data, _ = collect("ward", episodes=PATIENTS, seed=args.log_seed)
    rng = np.random.default_rng([0, args.split])
    test = np.zeros(PATIENTS, bool)
    test[rng.choice(PATIENTS, size=PATIENTS // 11, replace=False)] = True
    counts = [int(f) for f in args.folds.split(",")]
    with tempfile.TemporaryDirectory() as tmp:
        store = Store(Path(tmp))
        store.write("ward", data.select_episodes(~test))
        corpus = store.corpus("ward")

        def train(folds: int, rule: str):
            def run(_i: int) -> dict:
                old, tuning.FOLDS = tuning.FOLDS, folds
                hook = tuning.abc_validation
                if rule == "loss":  # the search's folds unscored (no AUC: the log-loss
                    calls = []      # alone); the final model's validation as before

                    def first_unscored(actions, n_actions, k=None):
                        calls.append(1)
                        if len(calls) == 1:
                            return lambda *_a: {"val_abc_auc": None}
                        return hook(actions, n_actions, k)
                    tuning.abc_validation = first_unscored
                try:
                    metrics = train_corpus(corpus, "default", overwrite=True, mode="imitation",
                                           threads=1, seed=args.split).metrics
                finally:
                    tuning.FOLDS, tuning.abc_validation = old, hook
                return metrics["selection"]
            return run

        cases = {f"folds {f}, {rule}": train(f, rule) for f in counts
                 for rule in args.rules.split(",")}
        runs = h.interleave(cases, args.repeats)
    base = runs[next(iter(cases))]
    rows = [h.row(case, corpus.n_rows, r,
                  search_s=float(np.median([s["search_seconds"] for s in r.outs])),
                  chosen=[s["chosen"] for s in r.outs], ratio=h.paired(base, r))
            for case, r in runs.items()]
    h.emit(rows, args.format)


if __name__ == "__main__":
    main()
