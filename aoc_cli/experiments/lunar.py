"""LunarLanderContinuous (paper Table "Performance comparison on LunarLanderContinuous"):
every method at every data size, plus the data's own average return.

The paper's sizes are 0.1M, 0.2M, 0.3M, 0.5M and 1M rows; the behaviour data here is
gymnasium's heuristic lander with action noise of std 0, 0.25, 0.5 and 1 (see
``aoc_cli.envs.lunar``), not the paper's (unpublished) mix, so the data's own return differs.
"""

from __future__ import annotations

from aoc_cli.experiments import paper
from aoc_cli.experiments.beliefs import BELIEF_ROWS, belief_session, prepare_beliefs
from aoc_cli.experiments.cells import Cell, Plan
from aoc_cli.experiments.common import Context, belief_config, make_task_env, session
from aoc_cli.experiments.methods import DATA, data_values, row_values
from aoc_cli.experiments.results import result_row
from aoc_cli.store import DEFAULT_MODEL

METHODS = ["aoc", "aoc-dynamics", "aoc-critic", "aoc-reward", "knn", "1nn", "knn-belief", "1nn-belief", "bc", "td3bc", "cql", "mpc",
           "zero", "random"]
SCALES = {
    "tiny": {"sizes": [3_000], "paper_rows": [100_000], "episodes": 1, "seeds": 1,
             "epochs": 2, "patience": 2, "methods": ["aoc", "aoc-critic", "aoc-reward", "knn",
                                                     "bc", "zero"], "max_steps": 40,
             "critic_steps": 20},
    "quick": {"sizes": [30_000], "paper_rows": [100_000], "episodes": 2, "seeds": 1,
              "epochs": 30, "patience": 6, "critic_steps": 3_000,
              "methods": ["aoc", "aoc-dynamics", "aoc-critic", "aoc-reward", "knn", "bc", "td3bc",
                          "zero", "random"]},
    "full": {"sizes": [100_000, 200_000, 300_000, 500_000, 1_000_000],
             "paper_rows": [100_000, 200_000, 300_000, 500_000, 1_000_000], "episodes": 10,
             "seeds": 3, "epochs": 200, "patience": 10, "critic_steps": 10_000,
             "methods": METHODS},
}


def _cells(ctx: Context, scale: dict) -> list[Cell]:
    methods = ctx.pick_methods(scale["methods"])
    kinds = tuple(m for m in methods if m in BELIEF_ROWS)
    return [Cell("lunar", method, f"rows={size}", seed,
                 ("lunar", size, seed, "bc" in methods, kinds))
            for size in scale["sizes"] for seed in ctx.seeds for method in [DATA, *methods]]


def _prepare(ctx: Context, scale: dict, prep: tuple):
    _task, size, seed, bc, kinds = prep
    corpus = ctx.artefacts.corpus("lunar", rows=size, seed=seed)
    ctx.artefacts.model(corpus, DEFAULT_MODEL, belief_config(scale, "value", seed))
    if bc:
        ctx.artefacts.model(corpus, "bc", belief_config(scale, "imitation", seed))
    ctx.artefacts.index(corpus, DEFAULT_MODEL)
    prepare_beliefs(ctx, scale, corpus, list(kinds), seed)
    return corpus


def _run(ctx: Context, scale: dict, cell: Cell, corpus) -> dict:
    _task, method, setting, seed = cell.key
    if method == DATA:
        return {"rows": [result_row("lunar", "lunar", DATA, setting, seed,
                                    **data_values(corpus), note=f"corpus {corpus.name}")]}
    env = make_task_env("lunar", scale)
    if method in BELIEF_ROWS:
        s = belief_session(ctx, method, corpus, env, seed)
    else:
        s = session(corpus, env, seed=seed, **ctx.aoc_config)
    run = ctx.runner.run("aoc" if method in BELIEF_ROWS else method, s, env,
                         ctx.n_episodes(scale["episodes"]), seed,
                         label=f"{method} lunar {setting} seed {seed}")
    run.method = method
    return {"rows": [result_row("lunar", "lunar", method, setting, seed, **row_values(run))]}


def _figure(ctx: Context, scale: dict):
    sizes = dict(zip((f"rows={s}" for s in scale["sizes"]), scale["paper_rows"]))
    return lambda row: paper.lunar(row["method"], sizes.get(row["setting"], -1))


LUNAR = Plan(_cells, _prepare, _run, _figure)
