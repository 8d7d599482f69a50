"""Pendulum-Het experiments: methods x data sizes, the epsilon ablation, the k ablation.

* ``pendulum-het`` (paper Table "Results on the Heterogeneous Pendulum"): every method at every
  data size, evaluated in the normal system from gymnasium's random start (``pendulum-het``) and
  from the paper's upright start (``pendulum-het-upright``), plus the data's own average return.
  At the full scale the upright task has its own corpus (collected from the upright start, as
  the paper did); at the quick and tiny scales it is evaluated with the random-start corpus and
  models (the corpus covers the upright region; one training instead of two). A diagnostic
  row, ``aoc-normal-rows``, is AOC restricted to the evaluation system's rows (see ORACLE);
  ``aoc-dynamics`` is AOC with aoc's auxiliary dynamics head (see DYNAMICS); ``aoc-critic``
  and ``aoc-reward`` are AOC with the reference code's beliefs, ``aoc-gamma0.9`` AOC with the
  paper's value belief on the return-to-go at gamma 0.9 (aoc_cli/experiments/beliefs.py).
* ``epsilon`` (paper Table "epsilon controls the conservation"): AOC with epsilon in
  {0.3, 0.5, 0.9, 1.0} at the middle data size, on the scale's ablation tasks (the quick
  scale: random and upright start), with the paper's model and with the dynamics head.
* ``k`` (paper Table "cardinality of the corpus subset"): AOC with k in {1, 10, 2 (d_b + 1), 100},
  likewise.

The paper's pendulum figures are for the upright start; they are shown beside both tasks.
"""

from __future__ import annotations

from aoc_cli.experiments import paper
from aoc_cli.experiments.beliefs import BELIEF_ROWS, belief_session, prepare_beliefs
from aoc_cli.experiments.cells import Cell, Plan
from aoc_cli.experiments.common import Context, belief_config, make_task_env, session
from aoc_cli.experiments.methods import DATA, data_values, row_values
from aoc_cli.experiments.results import result_row
from aoc_cli.decompose import default_k
from aoc_cli.rows import row_selection
from aoc_cli.store import DEFAULT_MODEL

TASKS = ("pendulum-het", "pendulum-het-upright")
METHODS = ["aoc", "aoc-dynamics", "aoc-critic", "aoc-reward", "aoc-gamma0.9", "aoc-normal-rows",
           "knn", "1nn",
           "knn-belief", "1nn-belief",
           "bc", "td3bc", "cql", "mpc", "zero", "random"]

SCALES = {
    "tiny": {"sizes": [2_000], "paper_rows": [100_000], "episodes": 1, "seeds": 1,
             "epochs": 2, "patience": 2, "upright_data": "shared", "mid": 2_000, "max_steps": 40,
             "critic_steps": 20,
             "ablation_tasks": ["pendulum-het"]},
    "quick": {"sizes": [30_000], "paper_rows": [100_000], "episodes": 4, "seeds": 1,
              "epochs": 40, "patience": 6, "upright_data": "shared", "mid": 30_000,
              "critic_steps": 3_000,
              "ablation_tasks": ["pendulum-het", "pendulum-het-upright"],
              "methods": [m for m in METHODS if m != "cql"]},  # CQL: too slow on this CPU
    "full": {"sizes": [100_000, 300_000, 600_000], "paper_rows": [100_000, 300_000, 600_000],
             "episodes": 10, "seeds": 8, "epochs": 200, "patience": 10, "upright_data": "own",
             "critic_steps": 10_000,
             "mid": 300_000, "ablation_tasks": ["pendulum-het", "pendulum-het-upright"]},
}
EPSILONS = (0.3, 0.5, 0.9, 1.0)
#: A diagnostic, not a method of the paper: AOC (same model, same index) whose decompositions
#: may only use rows of the evaluation system (``--select system=normal``). The gap between it
#: and ``aoc`` is what the belief fails to tell apart about the two systems.
ORACLE = "aoc-normal-rows"
#: aoc's extension, not the paper's objective: AOC whose value model (``dynamics``, its own
#: index) also learns the auxiliary dynamics head (``aoc train --dynamics-weight 1``), which
#: gives the belief a reason to tell the two systems apart (docs/notes/belief.md).
DYNAMICS = "aoc-dynamics"
DYNAMICS_WEIGHT = 1.0


def _variant(ctx: Context, method: str, corpus, env, task: str, seed: int):
    """The session of aoc's other rows: ORACLE (the normal system's rows only) or a belief row
    (aoc-dynamics, aoc-critic, aoc-reward: its own model and index, bench/beliefs.py)."""
    if method == ORACLE:
        normal = row_selection(corpus, {"system": ["normal"]})
        return session(corpus, env, seed=seed, selection=normal, **ctx.aoc_config)
    return belief_session(ctx, method, corpus, env, seed)


def _k_values(d_b: int) -> list[int]:
    return [1, 10, default_k(d_b), 100]


def _data_task(scale: dict, task: str) -> str:
    return task if (task == "pendulum-het" or scale["upright_data"] == "own") else "pendulum-het"


def _prepare(ctx: Context, scale: dict, prep: tuple):
    """Corpus, value model (+ bc model, + the dynamics-head model and its index, + the models
    and indexes of the belief rows) and default index of ``prep`` = (data task, rows, seed,
    bc, dynamics, belief rows)."""
    data_task, rows, seed, bc, dynamics, beliefs = prep
    corpus = ctx.artefacts.corpus(data_task, rows=rows, seed=seed)
    ctx.artefacts.model(corpus, DEFAULT_MODEL, belief_config(scale, "value", seed))
    if dynamics:
        ctx.artefacts.model(corpus, "dynamics", belief_config(scale, "value", seed,
                                                              dynamics_weight=DYNAMICS_WEIGHT))
        ctx.artefacts.index(corpus, "dynamics")
    prepare_beliefs(ctx, scale, corpus, [m for m in beliefs if m != DYNAMICS], seed)
    if bc:
        ctx.artefacts.model(corpus, "bc", belief_config(scale, "imitation", seed))
    ctx.artefacts.index(corpus, DEFAULT_MODEL)
    return corpus


def _het_cells(ctx: Context, scale: dict) -> list[Cell]:
    methods = ctx.pick_methods(scale.get("methods", METHODS))
    beliefs = tuple(m for m in methods if m in BELIEF_ROWS)
    cells = []
    for size in scale["sizes"]:
        for seed in ctx.seeds:
            for task in TASKS:
                prep = (_data_task(scale, task), size, seed, "bc" in methods,
                        DYNAMICS in methods, beliefs)
                cells += [Cell(task, method, f"rows={size}", seed, prep)
                          for method in [DATA, *methods]]
    return cells


def _het_run(ctx: Context, scale: dict, cell: Cell, corpus) -> dict:
    task, method, setting, seed = cell.key
    if method == DATA:
        return {"rows": [result_row("pendulum-het", task, DATA, setting, seed,
                                    **data_values(corpus), note=f"corpus {corpus.name}")]}
    env = make_task_env(task, scale)
    if method == ORACLE or method in BELIEF_ROWS:
        run = ctx.runner.run("aoc", _variant(ctx, method, corpus, env, task, seed),
                             env, ctx.n_episodes(scale["episodes"]), seed,
                             label=f"{method} {task} {setting} seed {seed}")
        run.method = method
    else:
        s = session(corpus, env, seed=seed, **ctx.aoc_config)
        run = ctx.runner.run(method, s, env, ctx.n_episodes(scale["episodes"]),
                             seed, label=f"{task} {setting} seed {seed}")
    return {"rows": [result_row("pendulum-het", task, method, setting, seed,
                                **row_values(run))]}


def _het_figure(ctx: Context, scale: dict):
    sizes = dict(zip((f"rows={s}" for s in scale["sizes"]), scale["paper_rows"]))
    return lambda row: paper.pendulum(row["method"], sizes.get(row["setting"], -1))


PENDULUM_HET = Plan(_het_cells, _prepare, _het_run, _het_figure)


def _ablation_cells(ctx: Context, scale: dict, settings) -> list[Cell]:
    cells = []
    for seed in ctx.seeds:
        for task in scale["ablation_tasks"]:
            prep = (_data_task(scale, task), scale["mid"], seed, False, True, ())
            for setting, config in settings(belief_config(scale, "value", seed)):
                for method in ("aoc", DYNAMICS):
                    cells.append(Cell(task, method, setting, seed, prep,
                                      tuple(sorted(config.items()))))
    return cells


def _ablation_run(name: str):
    def run(ctx: Context, scale: dict, cell: Cell, corpus) -> dict:
        task, method, setting, seed = cell.key
        env = make_task_env(task, scale)
        model_id = DEFAULT_MODEL if method == "aoc" else "dynamics"
        s = session(corpus, env, model_id=model_id, seed=seed,
                    **{**ctx.aoc_config, **dict(cell.args)})
        run = ctx.runner.run("aoc", s, env, ctx.n_episodes(scale["episodes"]), seed,
                             label=f"{method} {task} {setting} seed {seed}")
        return {"rows": [result_row(name, task, method, setting, seed, **row_values(run))]}

    return run


def _epsilon_settings(config):
    return [(f"epsilon={e:g}", {"epsilon": e}) for e in EPSILONS]


def _k_settings(config):
    """The k values of the paper's table; 2 (d_b + 1) from the model's belief dimension."""
    return [(f"k={k}", {"k": k}) for k in _k_values(config.belief_dim)]


EPSILON = Plan(lambda ctx, scale: _ablation_cells(ctx, scale, _epsilon_settings), _prepare,
               _ablation_run("epsilon"),
               lambda ctx, scale: lambda row: paper.epsilon(float(row["setting"].split("=")[1])))
K = Plan(lambda ctx, scale: _ablation_cells(ctx, scale, _k_settings), _prepare,
         _ablation_run("k"),
         lambda ctx, scale: lambda row: paper.k(int(row["setting"].split("=")[1])))
