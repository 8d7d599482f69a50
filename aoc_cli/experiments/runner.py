"""`aoc bench`: run an experiment end to end and write its tables and plots.

>>> from aoc_cli.experiments import run_experiment
>>> report = run_experiment("two-gates", scale="quick", out="bench/two-gates")  # doctest: +SKIP

Outputs in ``out``: results.csv, summary.json, summary.md and PNG plots (see
:mod:`aoc_cli.experiments.results`). Artefacts (corpora, models, indexes) go to the bench store and
are reused across runs and experiments (:mod:`aoc_cli.experiments.prepare`).
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from pathlib import Path

from aoc_cli.baselines import BASELINES
from aoc_cli.experiments import lunar, maze, ood, paper, pendulum, plots
from aoc_cli.experiments.execute import execute
from aoc_cli.experiments.common import SCALES, Context
from aoc_cli.experiments.methods import Budget, Runner
from aoc_cli.experiments.prepare import Artefacts
from aoc_cli.experiments.results import summarize_rows, summary_markdown, write_outputs
from aoc_cli.control.config import ControllerConfig, given_settings
from aoc_cli.errors import AocError, BadSetting, param

RETURN = [("return_mean", "return"), ("success_rate", "success")]


@dataclass(frozen=True)
class Experiment:
    name: str
    title: str
    plan: object       # a cells.Plan
    scales: dict
    metrics: list
    paper_label: str = "paper"


EXPERIMENTS = {e.name: e for e in [
    Experiment("pendulum-het", "Pendulum-Het: methods x data sizes", pendulum.PENDULUM_HET,
               pendulum.SCALES, [("return_mean", "return"), ("seconds_per_step", "s/step")],
               "paper (upright start)"),
    Experiment("epsilon", "Pendulum-Het: the residual quantile epsilon", pendulum.EPSILON,
               pendulum.SCALES, [("return_mean", "return"), ("mean_residual", "residual")],
               "paper (upright, 300k)"),
    Experiment("k", "Pendulum-Het: neighbours k", pendulum.K, pendulum.SCALES,
               [("return_mean", "return"), ("mean_residual", "residual")],
               "paper (upright, 300k)"),
    Experiment("maze-adapt", "Maze: re-sampling pi1 (no retraining)", maze.MAZE_ADAPT,
               maze.SCALES, [("success_rate", "success"), ("upper_gate", "upper gate /100"),
                             ("lower_gate", "lower gate /100"), ("return_mean", "return")],
               "paper (success / upper / lower)"),
    Experiment("two-gates", "Two gates: epsilon and conservatism", maze.TWO_GATES,
               maze.TWO_GATES_SCALES, RETURN),
    Experiment("lunar", "LunarLanderContinuous: methods x data sizes", lunar.LUNAR,
               lunar.SCALES, [("return_mean", "return"), ("success_rate", "success"),
                              ("seconds_per_step", "s/step")]),
    Experiment("ood", "OOD detection: action noise after step T", ood.OOD, ood.SCALES,
               [("ood_delay", "delay (steps)"), ("ood_flagged", "flagged after T"),
                ("ood_false_flags", "flags before T"), ("mean_residual", "residual"),
                ("return_mean", "return")], "paper"),
]}
ORDER = list(EXPERIMENTS)

#: Budgets of the black-box baselines per scale.
BUDGETS = {
    "tiny": Budget(offline_rl_steps=20, mpc_epochs=1, mpc_samples=20, mpc_horizon=5),
    "quick": Budget(offline_rl_steps=3_000, mpc_epochs=15, mpc_samples=200, mpc_horizon=15),
    "full": Budget(offline_rl_steps=100_000, mpc_epochs=30, mpc_samples=300, mpc_horizon=20),
}


#: AOC's rows in the bench: the paper's AOC, aoc's diagnostics and the other beliefs (see
#: bench/pendulum.py, bench/beliefs.py).
AOC_METHODS = ("aoc", "aoc-normal-rows", "aoc-dynamics", "aoc-critic", "aoc-reward",
               "aoc-gamma0.9")


#: Experiments that sweep the data size, and so take ``sizes`` (rows per corpus).
SIZED = ("pendulum-het", "lunar")
#: The controller setting an experiment varies (so takes from no one else).
VARIED = {"epsilon": "epsilon", "two-gates": "epsilon", "k": "k"}


def check(name: str, scale: str, seeds: int | None, episodes: int | None,
          methods: list[str] | None = None, controller: dict | None = None,
          sizes: list[int] | None = None, behaviour: str = "mix",
          workers: int | None = None) -> None:
    """Bad experiment, scale, counts, sizes, method names, AOC settings or workers -> AocError."""
    if behaviour not in ("mix", "replay"):
        raise BadSetting("behaviour", behaviour,
                         f"unknown {param('behaviour')} {behaviour!r}: use mix or replay")
    if behaviour != "mix" and name not in SIZED:
        raise BadSetting("behaviour", behaviour, f"{param('behaviour', behaviour)} applies to "
                         f"{' and '.join(SIZED)}, not {name}")
    if name != "all" and name not in EXPERIMENTS:
        raise AocError(f"unknown experiment {name!r}: use one of {', '.join(ORDER)} or all")
    if scale not in SCALES:
        raise AocError(f"unknown scale {scale!r}: use one of {', '.join(SCALES)}")
    if seeds is not None and seeds < 1:
        raise BadSetting("seeds", seeds, f"{param('seeds')} must be >= 1, got {seeds}")
    if episodes is not None and episodes < 1:
        raise BadSetting("episodes", episodes, f"{param('episodes')} must be >= 1, got {episodes}")
    given = given_settings(controller)
    varied = VARIED.get(name)
    if varied in given:
        raise BadSetting(varied, given[varied], f"{param(varied)} does not apply to {name}: "
                         f"{varied} is what it varies")
    ControllerConfig(**given)  # checks each setting given
    if methods:
        unknown = [m for m in methods if m not in AOC_METHODS and m not in BASELINES]
        if unknown:
            raise AocError(f"unknown method(s) {', '.join(unknown)}: use "
                           f"{', '.join([*AOC_METHODS, *BASELINES])}")
    if workers is not None and workers < 1:
        raise BadSetting("workers", workers, f"{param('workers')} must be >= 1, got {workers}")
    if sizes is not None:
        if name not in SIZED:
            raise BadSetting("sizes", sizes, f"{param('sizes')} applies to {' and '.join(SIZED)} "
                             f"(the data-size sweeps), not to {name}")
        if not sizes or any(n < 100 for n in sizes):
            raise BadSetting("sizes", sizes,
                             f"{param('sizes')} must be row counts >= 100, got {sizes}")


def sized(params: dict, sizes: list[int] | None) -> dict:
    """A scale's parameters with its data sizes replaced by ``sizes`` (rows per corpus); the
    paper's column shows a figure where a size is one of the paper's own."""
    if sizes is None:
        return params
    return {**params, "sizes": list(sizes), "paper_rows": list(sizes)}


def run_experiment(name: str, scale: str = "full", seeds: int | None = None,
                   out: str | Path | None = None, store: str | Path = "bench/store",
                   episodes: int | None = None, methods: list[str] | None = None,
                   log=None, progress=None, controller: dict | None = None,
                   sizes: list[int] | None = None,
                   behaviour: str = "mix", workers: int | None = None,
                   address: str | None = None) -> dict:
    """Run experiment ``name`` at ``scale`` (tiny | quick | full); write and return its report:
    ``{"experiment", "out", "rows", "summary", "plots", "built", "seconds"}``.

    Its cells (:mod:`aoc_cli.experiments.cells`) run here one after the other, or as Ray tasks with
    ``workers`` (a local Ray with that many CPUs) or ``address`` (an existing cluster; also
    ``$RAY_ADDRESS`` when ``workers`` is given); the rows are the same. Finished cells are
    kept in ``out/cells/`` and taken by a re-run with the same settings and code.

    ``controller`` (ControllerConfig fields given, {field: value}; a ControllerConfig) applies
    to AOC over each task's own settings, but not the setting the experiment varies
    (``VARIED``: an error); ``sizes`` replaces the scale's data sizes of the
    data-size sweeps (``SIZED``), e.g. one of the paper's sizes with the full scale's training
    and episodes; ``behaviour="replay"`` collects their corpora as replay buffers (an agent
    that starts random and improves, aoc_cli/envs/replay.py)."""
    check(name, scale, seeds, episodes, methods, controller, sizes, behaviour, workers)
    exp = EXPERIMENTS[name]
    params = sized(exp.scales[scale], sizes)
    out = Path(out) if out is not None else Path("bench") / name
    out.mkdir(parents=True, exist_ok=True)
    n_seeds = seeds if seeds is not None else int(params["seeds"])
    artefacts = Artefacts(store, log=log, progress=progress, behaviour=behaviour)
    runner = Runner(BUDGETS[scale], progress=progress, log=log)
    aoc_config = given_settings(controller)
    ctx = Context(name, scale, out, artefacts, runner, list(range(n_seeds)), episodes,
                  methods, log, aoc_config=aoc_config)
    started = time.perf_counter()
    rows = execute(exp.plan, ctx, params, workers=workers, address=address, progress=progress)
    figure = exp.plan.figure(ctx, params)
    summary = summarize_rows(rows, figure)
    _plot(exp, summary, ctx)
    seconds = time.perf_counter() - started
    header = (f"Scale `{scale}`, seeds {n_seeds}, {seconds / 60:.1f} min"
              + (f", AOC with epsilon = {aoc_config['epsilon']:g}"
                 if "epsilon" in aoc_config else "")
              + (f", residual cap {aoc_config['residual_cap']:g} x typical p90"
                 if "residual_cap" in aoc_config else "")
              + "".join(f", AOC with {k} = {v}" for k, v in aoc_config.items()
                        if k not in ("epsilon", "residual_cap"))
              + (f", {behaviour} data" if behaviour != "mix" else "")
              + ". Mean ± std across "
              "seeds (one seed: across its episodes). Plots: "
              + ", ".join(f"[{p}]({p})" for p in ctx.plots))
    markdown = summary_markdown(exp.title, summary, exp.metrics, header, exp.paper_label)
    write_outputs(out, name, rows, summary, markdown,
                  {"scale": scale, "seeds": n_seeds, "sizes": params.get("sizes"),
                   "behaviour": behaviour,
                   "seconds": seconds, "plots": ctx.plots, "aoc_config": ctx.aoc_config,
                   "built": artefacts.built})
    return {"experiment": name, "out": str(out), "rows": rows, "summary": summary,
            "plots": ctx.plots, "built": artefacts.built, "seconds": seconds}


def _plot(exp: Experiment, summary: list[dict], ctx: Context) -> None:
    out = ctx.out
    if exp.name in ("pendulum-het", "lunar"):
        for task in dict.fromkeys(r["task"] for r in summary):
            name = f"{task}_returns.png"
            if plots.grouped_bars(summary, task, out / name, f"{task}: return by method"):
                ctx.plots.append(name)
    elif exp.name in ("epsilon", "k", "two-gates"):
        for task in dict.fromkeys(r["task"] for r in summary):
            name = f"{exp.name}_{task}.png"
            methods = {r["method"] for r in summary if r["task"] == task}
            drawn = plots.grouped_bars(summary, task, out / name,
                                       f"{task}: AOC by {exp.name}") if len(methods) > 1 \
                else plots.setting_bars(summary, task, "aoc", out / name,
                                        f"{task}: AOC by {exp.name}")
            if drawn:
                ctx.plots.append(name)
    elif exp.name == "maze-adapt":
        if plots.maze_adapt_curves(summary, paper.MAZE, out / "maze_adapt.png"):
            ctx.plots.append("maze_adapt.png")


# -- expected time --------------------------------------------------------------------------

#: Seconds per unit on this project's 2-core machine, measured while other jobs shared it
#: (see docs/notes/results-defaults-per-task.md); an idle machine is faster.
COST = {
    "train_row_epoch": 1.0e-4,      # belief model, one thread
    "epochs": 35,                   # early stopping ends near here (at most max_epochs)
    "step": {"aoc": 0.07, "aoc-normal-rows": 0.07, "aoc-dynamics": 0.07,
             "aoc-critic": 0.07, "aoc-reward": 0.07, "aoc-gamma0.9": 0.07,
             "knn-belief": 0.06, "1nn-belief": 0.05, "knn": 0.05,
             "1nn": 0.04, "bc": 0.002, "td3bc": 0.001, "cql": 0.001, "mpc": 0.01,
             "zero": 0.0002, "random": 0.0002},
    "offline_rl_step": {"td3bc": 0.033, "cql": 0.25},
    "critic_step": 0.1,             # --belief critic, batch 500, one thread
    "mpc_row_epoch": 2e-5,
    "rows_per_episode": {"maze": 20, "two-gates": 28},
    "collect_row": {"lunar": 3e-4},
}


def expected_seconds(name: str, scale: str, seeds: int | None = None,
                     episodes: int | None = None, methods: list[str] | None = None,
                     sizes: list[int] | None = None) -> float:
    """A rough estimate of a run's time on this machine (artefact reuse not counted)."""
    if name == "all":
        return sum(expected_seconds(n, scale, seeds, episodes, methods) for n in ORDER)
    exp = EXPERIMENTS[name]
    p = sized(exp.scales[scale], sizes if name in SIZED else None)
    budget = BUDGETS[scale]
    n_seeds = seeds if seeds is not None else int(p["seeds"])
    eps = episodes or int(p["episodes"])
    epochs = min(p.get("epochs", COST["epochs"]), COST["epochs"])
    step = COST["step"]
    total = 0.0

    def train(rows, models=1):
        return models * rows * epochs * COST["train_row_epoch"]

    def blackbox(ms, rows):
        t = 0.0
        for m in ms:
            if m in COST["offline_rl_step"]:
                t += budget.offline_rl_steps * COST["offline_rl_step"][m]
            elif m == "mpc":
                t += rows * budget.mpc_epochs * COST["mpc_row_epoch"]
        return t

    def critic(ms):
        return ("aoc-critic" in ms) * int(p.get("critic_steps", 10_000)) * COST["critic_step"]

    if name == "pendulum-het":
        ms = methods or p.get("methods", pendulum.METHODS)
        tasks = len(pendulum.TASKS)
        for rows in p["sizes"]:
            corpora = 2 if p["upright_data"] == "own" else 1
            # the dynamics head: ~40% more epochs
            models = 1 + ("bc" in ms) + 1.4 * ("aoc-dynamics" in ms) \
                + ("aoc-reward" in ms) + ("aoc-gamma0.9" in ms)
            total += n_seeds * corpora * (train(rows, models) + blackbox(ms, rows)
                                          + critic(ms))
            total += n_seeds * tasks * eps * 200 * sum(step.get(m, 0.01) for m in ms)
    elif name in ("epsilon", "k"):
        tasks = len(p["ablation_tasks"])
        total += n_seeds * train(p["mid"], 2.4)   # the paper's model and the dynamics head's
        total += n_seeds * tasks * 2 * 4 * eps * 200 * step["aoc"]
    elif name == "maze-adapt":
        rows = p["episodes_data"] * COST["rows_per_episode"]["maze"]
        total += n_seeds * train(rows)
        total += n_seeds * len(p["rates"]) * eps * 35 * step["aoc"]
        total += n_seeds * eps * 100 * sum(step.get(m, 0.01) for m in p["compare"])
    elif name == "two-gates":
        rows = p["episodes_data"] * COST["rows_per_episode"]["two-gates"]
        total += n_seeds * (train(rows) + len(p["epsilons"]) * eps * 32 * step["aoc"])
    elif name == "lunar":
        ms = methods or p["methods"]
        for rows in p["sizes"]:
            models = 1 + ("bc" in ms) + 1.4 * ("aoc-dynamics" in ms) + ("aoc-reward" in ms)
            total += n_seeds * (rows * COST["collect_row"]["lunar"]
                                + train(rows, models) + blackbox(ms, rows) + critic(ms))
            total += n_seeds * eps * 400 * sum(step.get(m, 0.01) for m in ms)
    elif name == "ood":
        for spec in p["tasks"]:
            rows = spec.get("rows") or spec.get("episodes", 0) * COST["rows_per_episode"]["maze"]
            total += n_seeds * (rows * min(spec["epochs"], COST["epochs"])
                                * COST["train_row_epoch"] + 2 * eps * 150 * step["aoc"])
    return total
