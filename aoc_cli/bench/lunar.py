"""LunarLanderContinuous (paper Table "Performance comparison on LunarLanderContinuous"):
every method at every data size, plus the data's own average return.

The paper's sizes are 0.1M, 0.2M, 0.3M, 0.5M and 1M rows; the behaviour data here is
gymnasium's heuristic lander with action noise of std 0, 0.25, 0.5 and 1 (see
``aoc_cli.envs.lunar``), not the paper's (unpublished) mix, so the data's own return differs.
"""

from __future__ import annotations

from aoc_cli.bench import paper
from aoc_cli.bench.beliefs import BELIEF_ROWS, belief_session, prepare_beliefs
from aoc_cli.bench.common import Context, belief_config, make_task_env, session
from aoc_cli.bench.methods import DATA, data_values, row_values
from aoc_cli.bench.results import result_row

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


def run_lunar(ctx: Context, scale: dict):

    methods = ctx.pick_methods(scale["methods"])
    env = make_task_env("lunar", scale)
    rows = []
    for size in scale["sizes"]:
        setting = f"rows={size}"
        for seed in ctx.seeds:
            corpus = ctx.artefacts.corpus("lunar", rows=size, seed=seed)
            ctx.artefacts.model(corpus, "default", belief_config(scale, "value", seed))
            if "bc" in methods:
                ctx.artefacts.model(corpus, "bc", belief_config(scale, "imitation", seed))
            ctx.artefacts.index(corpus, "default")
            prepare_beliefs(ctx, scale, corpus, methods, seed)
            s = session(corpus, env, "lunar", seed=seed, **ctx.aoc_config)
            rows.append(result_row("lunar", "lunar", DATA, setting, seed,
                                   **data_values(corpus), note=f"corpus {corpus.name}"))
            for method in methods:
                run = ctx.runner.run("aoc" if method in BELIEF_ROWS else method,
                                     belief_session(ctx, method, corpus, env, "lunar", seed)
                                     if method in BELIEF_ROWS else s, env,
                                     ctx.n_episodes(scale["episodes"]), seed,
                                     label=f"{method} lunar {setting} seed {seed}")
                run.method = method
                rows.append(result_row("lunar", "lunar", method, setting, seed,
                                       **row_values(run)))

    sizes = dict(zip((f"rows={s}" for s in scale["sizes"]), scale["paper_rows"]))

    def figure(row):
        return paper.lunar(row["method"], sizes.get(row["setting"], -1))

    return rows, figure
