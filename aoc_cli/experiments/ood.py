"""Out-of-distribution detection at control time (paper appendix "Identify Control Time OOD
Examples with AOC").

AOC runs as usual; from step T on, Gaussian noise (std ``noise`` times the action range)
disturbs every applied action (``rollout(..., noise_after=T, noise_std=noise)``), so the
history the controller sees leaves the data. The OOD monitor flags a step whose residual
leaves the running 3-sigma band. Per episode:

* delay: the first flagged step at or after T, minus T (episodes with no such flag have none);
* flagged: whether any step at or after T was flagged (the share of episodes is reported);
* false flags: flagged steps before T (no disturbance yet).

The same seeds run without noise (``noise=0``) as the control: there every flag is a false
alarm. Each run is scored against two bands: the monitor's running band of the episode's own
earlier steps (``band=running``), and a reference band per step learned from clean rollouts
on other episode seeds (``band=reference``, :func:`aoc_cli.control.monitor.reference_band`),
which knows that some steps always have a larger residual (the maze's hand-over).

The paper used BipedalWalker with a black-box sampler and noise after step 500; here
the tasks are pendulum-het (random start; its data holds uniformly random torques, so noisy
actions are not out of distribution there) and the maze (experts with small noise, noise
after step 12), with the uniform sampler and each task's controller settings.
"""

from __future__ import annotations

import numpy as np

from aoc_cli.experiments.cells import Cell, Plan
from aoc_cli.experiments.common import Context, belief_config, make_task_env, session
from aoc_cli.experiments.methods import row_values
from aoc_cli.experiments.results import result_row
from aoc_cli.control.monitor import flags_against
from aoc_cli.control.run import session_reference_band
from aoc_cli.report.plots import plot_rollout_curves, plt, save
from aoc_cli.store import DEFAULT_MODEL

#: The clean reference rollouts of bench seed s use the episode seeds of bench seed s + this.
REFERENCE_SEEDS = 500

SCALES = {
    "tiny": {"tasks": [
        {"task": "pendulum-het", "rows": 2_000, "T": 25, "epochs": 2, "patience": 2,
         "max_steps": 50},
        {"task": "maze", "episodes": 120, "T": 12, "epochs": 2, "patience": 2,
         "max_steps": 30}],
        "noise": 0.5, "episodes": 1, "seeds": 1},
    "quick": {"tasks": [
        {"task": "pendulum-het", "rows": 30_000, "T": 100, "epochs": 40, "patience": 6},
        {"task": "maze", "episodes": 1000, "T": 12, "epochs": 60, "patience": 8}],
        "noise": 0.5, "episodes": 4, "seeds": 1},
    "full": {"tasks": [
        {"task": "pendulum-het", "rows": 100_000, "T": 100, "epochs": 200, "patience": 10},
        {"task": "maze", "episodes": 1000, "T": 12, "epochs": 200, "patience": 10}],
        "noise": 0.5, "episodes": 10, "seeds": 3},
}


def episode_flags(flags, T: int) -> tuple[int | None, bool, int]:
    """(delay, flagged after T, false flags before T) of one episode's per-step flags."""
    flags = np.asarray(flags, bool)
    after = np.flatnonzero(flags[T:])
    delay = int(after[0]) if len(after) else None
    return delay, bool(len(after)), int(flags[:T].sum())


def ood_values(flag_runs, T: int) -> dict:
    """Mean delay, share flagged after T and false flags per episode, from per-step flags."""
    stats = [episode_flags(f, T) for f in flag_runs]
    delays = [d for d, _f, _n in stats if d is not None]
    return {
        "ood_delay": float(np.mean(delays)) if delays else None,
        "ood_flagged": float(np.mean([f for _d, f, _n in stats])) if stats else None,
        "ood_false_flags": float(np.mean([n for _d, _f, n in stats])) if stats else None,
    }


def _curves(results) -> dict:
    """Per-step means over episodes: residual, band edge, reward (arrays of the longest run)."""
    T = max(r.length for r in results)

    def mean_of(get):
        mat = np.full((len(results), T), np.nan)
        for i, r in enumerate(results):
            v = np.array([np.nan if x is None else x for x in get(r)], dtype=float)
            v[~np.isfinite(v)] = np.nan
            mat[i, :len(v)] = v[:T]
        import warnings

        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)  # steps no episode reached
            return np.nanmean(mat, axis=0)

    return {"residual": mean_of(lambda r: r.residuals),
            "band": mean_of(lambda r: getattr(getattr(r, "monitor", None), "upper", [])),
            "reward": mean_of(lambda r: r.rewards)}


def plot_ood(curves: dict, T: int, path, title: str, reference=None) -> None:
    """Mean residual (with the mean 3-sigma band edge, shaded) and mean reward per step;
    ``reference`` (T,), the reference band, dashed."""
    fig, (ax_r, ax_res) = plt.subplots(2, 1, figsize=(8, 6), sharex=True)
    for label, c in curves.items():
        t = np.arange(len(c["reward"]))
        ax_r.plot(t, c["reward"], lw=1.2, label=label)
        line, = ax_res.plot(t, c["residual"], lw=1.2, label=f"{label}: residual")
        ax_res.fill_between(t, 0, c["band"], color=line.get_color(), alpha=0.12,
                            label=f"{label}: 3-sigma band")
    if reference is not None:
        ax_res.plot(np.arange(len(reference)), reference, color="black", ls="--", lw=1,
                    label="reference band (clean rollouts)")
    for ax in (ax_r, ax_res):
        ax.axvline(T, color="grey", ls=":", lw=1)
    ax_r.set_ylabel("reward (mean)")
    ax_res.set_ylabel("corpus residual (mean)")
    ax_res.set_xlabel(f"step (noise from step {T})")
    ax_r.legend(fontsize=8)
    ax_res.legend(fontsize=8, loc="upper left")
    fig.suptitle(title)
    save(fig, path)


def _cells(ctx: Context, scale: dict) -> list[Cell]:
    """One cell per task and seed: the clean reference rollouts, then AOC without and with
    noise (both scored against that reference)."""
    return [Cell(spec["task"], "aoc", "noise", seed, (i, seed), (i,))
            for i, spec in enumerate(scale["tasks"]) for seed in ctx.seeds]


def _prepare(ctx: Context, scale: dict, prep: tuple):
    i, seed = prep
    spec = scale["tasks"][i]
    corpus = ctx.artefacts.corpus(spec["task"], rows=spec.get("rows"),
                                  episodes=spec.get("episodes"), seed=seed)
    ctx.artefacts.model(corpus, DEFAULT_MODEL, belief_config(spec, "value", seed))
    ctx.artefacts.index(corpus, DEFAULT_MODEL)
    return corpus


def _run(ctx: Context, scale: dict, cell: Cell, corpus) -> dict:
    spec, seed = scale["tasks"][cell.args[0]], cell.seed
    task, T = spec["task"], int(spec["T"])
    env = make_task_env(task, spec)
    rows, curves = [], {}
    n = ctx.n_episodes(scale["episodes"])
    s = session(corpus, env, seed=seed, **ctx.aoc_config)
    ref = ctx.runner.run("aoc", s, env, n, seed + REFERENCE_SEEDS,
                         label=f"{task} clean reference seed {seed}")
    band = None
    if ref.status == "ok":
        band = session_reference_band(s, [r.residuals for r in ref.results])
    for noise in (0.0, float(scale["noise"])):
        s = session(corpus, env, seed=seed, **ctx.aoc_config)
        run = ctx.runner.run("aoc", s, env, n, seed,
                             noise_after=T if noise > 0 else None, noise_std=noise,
                             label=f"{task} noise {noise:g} seed {seed}")
        values = row_values(run)
        scored = None
        if run.status == "ok" and band is not None:
            scored = dict(values, **ood_values(
                [flags_against(r.residuals, band) for r in run.results], T))
        if run.status == "ok":
            values.update(ood_values([r.ood for r in run.results], T))
            if seed == ctx.seeds[0]:
                curves[f"noise {noise:g}"] = _curves(run.results)
                name = f"ood_{task}_noise{noise:g}_episodes.png"
                plot_rollout_curves(run.results, ctx.out / name,
                                    title=f"{task}: AOC, noise {noise:g} after step {T}",
                                    noise_after=T)
                ctx.plots.append(name)
        rows.append(result_row("ood", task, "aoc", f"noise={noise:g}, band=running", seed,
                               **values))
        if scored is not None:
            rows.append(result_row("ood", task, "aoc", f"noise={noise:g}, band=reference",
                                   seed, **scored))
    extra = {"curves": curves, "band": band} if seed == ctx.seeds[0] else {}
    return {"rows": rows, "extra": extra}


def _finish(ctx: Context, scale: dict, results) -> None:
    """Per task: the mean residual and reward per step of the first seed, with its band."""
    for cell, result in results:
        spec = scale["tasks"][cell.args[0]]
        curves = result.extra.get("curves")
        if cell.seed != ctx.seeds[0] or not curves:
            continue
        band = result.extra.get("band")
        name = f"ood_{cell.task}_mean.png"
        plot_ood({k: {m: np.asarray(v, dtype=float) for m, v in c.items()}
                  for k, c in curves.items()}, int(spec["T"]), ctx.out / name,
                 f"{cell.task}: residual and reward per step, noise after step {spec['T']}",
                 reference=None if band is None else np.asarray(band, dtype=float))
        ctx.plots.append(name)


OOD = Plan(_cells, _prepare, _run, lambda ctx, scale: (lambda row: None), _finish)
