"""Collect benchmark (issue 3): rows per second of each built-in task's behaviour mix, and the
whole `aoc collect` (collect + store write) for pendulum-het.

    .venv/bin/python benchmarks/perf/collect.py [--repeats 5] [--pendulum-rows 100000]
                                           [--lunar-rows 20000] [--tasks ...] [-f json]

Goal: 100k pendulum-het rows in <= 30 s on this machine. pendulum-het is stepped for all of its
episodes at once with numpy (the same equations as gymnasium's Pendulum, bit for bit); lunar
steps gymnasium's Box2D LunarLanderContinuous one episode at a time with the heuristic lander;
maze and two-gates run their default episode counts vectorised. The tasks are timed in memory
(``aoc_cli.envs.collect``, no store write); the last row is the command in a fresh process
(imports, collect, HDF5 write). Reported: the median of ``--repeats`` runs (seed = run index)
and each run's time.
"""

from __future__ import annotations

import tempfile

import _harness as h

from aoc_cli.envs import collect


def main() -> None:
    ap = h.parser(__doc__, repeats=5)
    ap.add_argument("--pendulum-rows", type=int, default=100_000)
    ap.add_argument("--lunar-rows", type=int, default=20_000)
    ap.add_argument("--tasks", default="pendulum-het,pendulum-het-upright,maze,two-gates,lunar,"
                    "cli", help="the cases to run (cli: the aoc collect pendulum-het process)")
    args = ap.parse_args()
    budgets = {"pendulum-het": {"steps": args.pendulum_rows},
               "pendulum-het-upright": {"steps": args.pendulum_rows},
               "maze": {"episodes": 1000}, "two-gates": {"episodes": 500},
               "lunar": {"steps": args.lunar_rows}}
    rows = []
    for task in args.tasks.split(","):
        if task == "cli":
            with tempfile.TemporaryDirectory() as tmp:
                runs = h.interleave({"cli": lambda seed: h.aoc(
                    ["collect", "pendulum-het", "--steps", str(args.pendulum_rows), "--name",
                     f"p{seed}", "--seed", str(seed), "--format", "json"], store=tmp)},
                    args.repeats)["cli"]
            rows.append(h.row("aoc collect pendulum-het", args.pendulum_rows, runs))
        else:
            runs = h.repeat(lambda seed: collect(task, seed=seed, **budgets[task])[0],
                            args.repeats)
            rows.append(h.row(task, runs.out.n_rows, runs))
    h.emit(rows, args.format)


if __name__ == "__main__":
    main()
