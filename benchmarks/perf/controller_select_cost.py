"""What choosing the controller on held-out episodes costs ``aoc train`` on an icu-sepsis log
(docs/notes/benchmarks-rounds.md, "The controller chosen on held-out episodes").

    OMP_NUM_THREADS=1 .venv/bin/python benchmarks/perf/controller_select_cost.py
        [--episodes 10000] [--repeats 2] [--seed 0] [-f json]

A log of ``--episodes`` clinician episodes (``collect icu-sepsis``; the rules read its evidence
as they read a plain file's: rule 2 holds), trained as ``aoc train NAME`` trains it, one thread,
twice a round, interleaved: ``--no-select`` (one candidate's training: the model, rule 2's
controller) and with the selection (aoc_cli.training.controller_selection: the same training,
then the four candidates decided and valued by FQE on the validation episodes). One row per case: the
median wall and CPU seconds of the whole training; on the selection's row the selection's own
median seconds (its record, ``metrics.settings.controller_selection.seconds``), the ratio of
those to the same round's ``--no-select`` training (the goal: at most 1), the paired ratio of
the whole trainings, and what each run chose.
"""

from __future__ import annotations

import tempfile
from pathlib import Path

import _harness as h

h.omp_threads(1)

import numpy as np  # noqa: E402

import aoc_cli  # noqa: E402
from aoc_cli.envs import collect  # noqa: E402
from aoc_cli.store import Store  # noqa: E402


def main() -> None:
    ap = h.parser(__doc__, repeats=2)
    ap.add_argument("--episodes", type=int, default=10_000)
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args()
    data, _ = collect("icu-sepsis", episodes=args.episodes, seed=args.seed)
    with tempfile.TemporaryDirectory() as tmp:
        store = Store(Path(tmp))
        store.write("icu", data)

        def train(no_select: bool):
            def run(_i: int) -> dict:
                return aoc_cli.train("icu", store=tmp, overwrite=True, threads=1,
                                     seed=args.seed, no_select=no_select).metrics
            return run

        runs = h.interleave({"no-select": train(True), "select": train(False)}, args.repeats)
    base, sel = runs["no-select"], runs["select"]
    spent = [m["settings"]["controller_selection"]["seconds"] for m in sel.outs]
    rows = [h.row("no-select", data.n_rows, base,
                  chosen=[f"cap {m['controller'].get('residual_cap')}, penalty "
                          f"{m['controller'].get('support_penalty')}" for m in base.outs]),
            h.row("select", data.n_rows, sel, select_s=float(np.median(spent)),
                  select_over_training=float(np.median([s / w for s, w in
                                                        zip(spent, base.wall)])),
                  ratio=h.paired(base, sel),
                  chosen=[f"cap {m['controller'].get('residual_cap')}, penalty "
                          f"{m['controller'].get('support_penalty')}" for m in sel.outs])]
    h.emit(rows, args.format)


if __name__ == "__main__":
    main()
