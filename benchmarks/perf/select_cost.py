"""What choosing the settings by cross-validation costs ``aoc train`` on a ward-sized log
(docs/benchmarks.md, "Settings chosen by cross-validation").

    OMP_NUM_THREADS=1 .venv/bin/python benchmarks/perf/select_cost.py [--split 0]
        [--folds 1,3] [--repeats 3] [--log-seed 0] [-f json]

``aoc bench ward``'s patient split ``--split`` of the ward log (550 patients; its training
side, 500 patients, ~5,000 rows), the model trained as the bench trains it (``train_corpus``:
the settings left open chosen by validation, one thread), with the selection's folds set to
each of ``--folds`` (1: one validation split, the rule before; 3: the default now), the fold
counts interleaved round by round. One row per fold count: the median wall and CPU seconds of
the whole training, the search's own median seconds, what each run chose, and the ratio to
the first fold count (median of the rounds' ratios).
"""

from __future__ import annotations

import tempfile
from pathlib import Path

import _harness as h
import numpy as np

from aoc_cli.belief import select
from aoc_cli.belief.fit import train_corpus
from aoc_cli.envs import collect
from aoc_cli.store import Store

PATIENTS = 550


def main() -> None:
    ap = h.parser(__doc__, repeats=3)
    ap.add_argument("--split", type=int, default=0)
    ap.add_argument("--folds", default="1,3")
    ap.add_argument("--log-seed", type=int, default=0)
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

        def train(folds: int):
            def run(_i: int) -> dict:
                old, select.FOLDS = select.FOLDS, folds
                try:
                    metrics = train_corpus(corpus, "default", overwrite=True, mode="imitation",
                                           threads=1, seed=args.split).metrics
                finally:
                    select.FOLDS = old
                return metrics["selection"]
            return run

        runs = h.interleave({f"folds {f}": train(f) for f in counts}, args.repeats)
    base = runs[f"folds {counts[0]}"]
    rows = [h.row(case, corpus.n_rows, r,
                  search_s=float(np.median([s["search_seconds"] for s in r.outs])),
                  chosen=[s["chosen"] for s in r.outs], ratio=h.paired(base, r))
            for case, r in runs.items()]
    h.emit(rows, args.format)


if __name__ == "__main__":
    main()
