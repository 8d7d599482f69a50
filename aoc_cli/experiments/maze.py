"""Maze experiments: adaptivity by re-sampling pi1 (maze-adapt) and conservatism (two-gates).

* ``maze-adapt`` (paper Figure "behavior of AOC can be controlled by re-sampling" and its
  appendix table): one corpus and one model; for each rate in x4, x3, x2, x1, x0.75, x0.5,
  x0.25 a derived index re-samples pi1's rows (``resample={"policy=pi1": rate}``; an integer
  part repeats them, a fraction keeps that share of pi1's episodes), with no retraining. AOC
  runs from (0, 0) to (16, 0); reported: the success rate and how many rollouts pass the upper
  and the lower gate. The gate of a rollout is where its path first crosses the wall line
  x = 8 (from x < 8 to x >= 8): the crossing's y, interpolated on that step's segment, is the
  upper gate when y > 11.625 (half way between the gap around y = 8, [7.25, 8.75], and the gap
  at the top, [14.5, 16]) and the lower gate otherwise; a rollout that never crosses counts in
  neither. Counts are per 100 rollouts. The raw-feature kNN runs at x1 for comparison. AOC runs
  at epsilon 0.1 (:data:`MAZE_EPSILON`, what ``aoc train`` decides on a maze log's held-out
  episodes: aoc_cli.training.epsilon_rule).
* ``two-gates`` (paper Table "epsilon contributes to the conservative behaviours"): AOC with
  epsilon in {0.1, 0.3, 0.5, 0.7}; the return and a PNG of the trajectories per epsilon.
"""

from __future__ import annotations

import numpy as np

from aoc_cli.control import HistoryBuffer
from aoc_cli.envs import TASKS
from aoc_cli.experiments import paper
from aoc_cli.experiments.cells import Cell, Plan
from aoc_cli.experiments.common import Context, belief_config, make_task_env, session
from aoc_cli.experiments.methods import row_values
from aoc_cli.experiments.results import result_row
from aoc_cli.store import DEFAULT_INDEX, DEFAULT_MODEL

RATES = (4.0, 3.0, 2.0, 1.0, 0.75, 0.5, 0.25)
#: maze-adapt's epsilon (module docstring).
MAZE_EPSILON = 0.1
EPSILONS = (0.1, 0.3, 0.5, 0.7)
WALL_X = 8.0
GATE_SPLIT = (8.75 + 14.5) / 2.0  # 11.625

SCALES = {
    "tiny": {"episodes_data": 120, "episodes": 2, "seeds": 1, "epochs": 2, "patience": 2,
             "rates": (2.0, 1.0, 0.5), "compare": ["knn"], "max_steps": 30},
    "quick": {"episodes_data": 1000, "episodes": 20, "seeds": 1, "epochs": 60, "patience": 8,
              "rates": RATES, "compare": ["knn"]},
    "full": {"episodes_data": 1000, "episodes": 100, "seeds": 3, "epochs": 200,
             "patience": 10, "rates": RATES, "compare": ["knn", "1nn", "knn-belief"]},
}
TWO_GATES_SCALES = {
    "tiny": {"episodes_data": 60, "episodes": 2, "seeds": 1, "epochs": 2, "patience": 2,
             "epsilons": (0.1, 0.7)},
    "quick": {"episodes_data": 500, "episodes": 30, "seeds": 1, "epochs": 60, "patience": 8,
              "epsilons": EPSILONS},
    "full": {"episodes_data": 500, "episodes": 100, "seeds": 3, "epochs": 200, "patience": 10,
             "epsilons": EPSILONS},
}


def gate_of(path: np.ndarray) -> str | None:
    """'upper', 'lower' or None: the gate where a (T, 2) path first crosses x = 8."""
    p = np.asarray(path, dtype=np.float64)
    if len(p) < 2:
        return None
    x0, x1 = p[:-1, 0], p[1:, 0]
    cross = np.flatnonzero((x0 < WALL_X) & (x1 >= WALL_X))
    if len(cross) == 0:
        return None
    t = cross[0]
    frac = (WALL_X - p[t, 0]) / (p[t + 1, 0] - p[t, 0])
    y = p[t, 1] + frac * (p[t + 1, 1] - p[t, 1])
    return "upper" if y > GATE_SPLIT else "lower"


def gate_counts(results) -> tuple[float, float]:
    """(upper, lower) rollouts per 100 (module docstring)."""
    gates = [gate_of(np.asarray(r.observations)) for r in results]
    n = max(len(gates), 1)
    return 100.0 * gates.count("upper") / n, 100.0 * gates.count("lower") / n


#: The first move of each route from (0, 0): unit heading to pi1's goal (8, 16) and to
#: pi2's (8, 8), at the experts' mean speed 0.75.
START_PROBES = {"pi1": np.array([8.0, 16.0]) / np.hypot(8.0, 16.0) * 0.75,
                "pi2": np.array([8.0, 8.0]) / np.hypot(8.0, 8.0) * 0.75}


def start_probe(session) -> dict:
    """How the decomposition sees each route's first move at (0, 0), empty history.

    For the pi1-like and the pi2-like move: ``value_<p>`` (v_hat), ``residual_<p>``,
    ``pi1_nearest_<p>`` (the share of pi1 entries among its k nearest index entries, copies
    counted), ``distinct_nearest_<p>`` (distinct corpus rows among them) and ``pi1_support_<p>``
    (pi1's weight in its minimal corpus subset). Explains maze-adapt's gate shares: re-sampling
    changes the nearest entries, the decision follows v_hat among candidates that pass.
    """
    ctl, corpus = session.controller, session.corpus
    codes, labels = corpus.tag("policy")
    pi1 = codes == labels.index("pi1")
    moves = np.stack(list(START_PROBES.values()))
    history = HistoryBuffer(session.model.history_length, 2, 2, False).history()
    # the start observation and the empty history broadcast to the moves (the GRU runs once)
    beliefs = ctl.model.beliefs(np.zeros((1, 2), np.float32), moves, history)
    dec = session.index.decompose(beliefs, k=ctl.k, selection=ctl.selection)
    out = {}
    for j, name in enumerate(START_PROBES):
        nearest = dec.neighbours[j][dec.neighbours[j] >= 0]
        rows, w = dec.rows[j], dec.weights[j]
        out.update({f"value_{name}": float(dec.value[j]),
                    f"residual_{name}": float(dec.residual[j]),
                    f"pi1_nearest_{name}": float(pi1[nearest].mean()),
                    f"distinct_nearest_{name}": int(len(np.unique(nearest))),
                    f"pi1_support_{name}": float(w[(rows >= 0) & pi1[np.maximum(rows, 0)]].sum())})
    return out


def _index_id(rate: float) -> str:
    return DEFAULT_INDEX if rate == 1.0 else f"pi1x{rate:g}"


def _plot(ctx: Context, task: str, results, name: str, title: str) -> None:
    path = ctx.out / name
    TASKS[task].plot_trajectories([np.asarray(r.observations)[:, :2] for r in results], path,
                                  title=title)
    ctx.plots.append(name)


def _maze_cells(ctx: Context, scale: dict) -> list[Cell]:
    return [Cell("maze", method, f"rate={rate:g}", seed, ("maze", seed), (rate,))
            for seed in ctx.seeds for rate in scale["rates"]
            for method in ["aoc"] + (ctx.pick_methods(scale["compare"]) if rate == 1.0 else [])]


def _maze_prepare(ctx: Context, scale: dict, prep: tuple):
    seed = prep[1]
    corpus = ctx.artefacts.corpus("maze", episodes=scale["episodes_data"], seed=seed)
    ctx.artefacts.model(corpus, DEFAULT_MODEL, belief_config(scale, "value", seed))
    for rate in scale["rates"]:
        resample = None if rate == 1.0 else {"policy=pi1": rate}
        ctx.artefacts.index(corpus, DEFAULT_MODEL, _index_id(rate), resample=resample, seed=seed)
    return corpus


def _maze_run(ctx: Context, scale: dict, cell: Cell, corpus) -> dict:
    seed, method, (rate,) = cell.seed, cell.method, cell.args
    env = make_task_env("maze", scale)
    s = session(corpus, env, index_id=_index_id(rate), seed=seed,
                **{"epsilon": MAZE_EPSILON, **ctx.aoc_config})
    run = ctx.runner.run(method, s, env, ctx.n_episodes(scale["episodes"]), seed,
                         label=f"maze x{rate:g} seed {seed}")
    values = row_values(run)
    if run.status == "ok":
        values["upper_gate"], values["lower_gate"] = gate_counts(run.results)
        if seed == ctx.seeds[0]:
            _plot(ctx, "maze", run.results, f"maze_{method}_x{rate:g}.png",
                  f"{method}, pi1 x{rate:g}: success {values['success_rate']:.0%}")
    return {"rows": [result_row("maze-adapt", "maze", method, cell.setting, seed, **values)]}


def _maze_figure(ctx: Context, scale: dict):
    def figure(row):
        fig = paper.maze(float(row["setting"].split("=")[1]))
        return None if fig is None or row["method"] != "aoc" else fig

    return figure


MAZE_ADAPT = Plan(_maze_cells, _maze_prepare, _maze_run, _maze_figure)


def _two_gates_cells(ctx: Context, scale: dict) -> list[Cell]:
    return [Cell("two-gates", "aoc", f"epsilon={eps:g}", seed, ("two-gates", seed), (eps,))
            for seed in ctx.seeds for eps in scale["epsilons"]]


def _two_gates_prepare(ctx: Context, scale: dict, prep: tuple):
    seed = prep[1]
    corpus = ctx.artefacts.corpus("two-gates", episodes=scale["episodes_data"], seed=seed)
    ctx.artefacts.model(corpus, DEFAULT_MODEL, belief_config(scale, "value", seed))
    ctx.artefacts.index(corpus, DEFAULT_MODEL)
    return corpus


def _two_gates_run(ctx: Context, scale: dict, cell: Cell, corpus) -> dict:
    seed, (eps,) = cell.seed, cell.args
    env = make_task_env("two-gates", scale)
    s = session(corpus, env, seed=seed, **{**ctx.aoc_config, "epsilon": eps})
    run = ctx.runner.run("aoc", s, env, ctx.n_episodes(scale["episodes"]), seed,
                         label=f"two-gates epsilon {eps:g} seed {seed}")
    values = row_values(run)
    if run.status == "ok" and seed == ctx.seeds[0]:
        _plot(ctx, "two-gates", run.results, f"two_gates_epsilon{eps:g}.png",
              f"AOC, epsilon {eps:g}: return {values['return_mean']:.2f}")
    return {"rows": [result_row("two-gates", "two-gates", "aoc", cell.setting, seed,
                                **values)]}


def _two_gates_figure(ctx: Context, scale: dict):
    return lambda row: paper.two_gates(float(row["setting"].split("=")[1]))


TWO_GATES = Plan(_two_gates_cells, _two_gates_prepare, _two_gates_run, _two_gates_figure)
