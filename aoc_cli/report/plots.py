"""PNG plots (matplotlib, Agg backend): residual and reward curves, bars with error bars."""

from __future__ import annotations

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from aoc_cli.envs import TASKS  # noqa: E402
from aoc_cli.store import atomic_path  # noqa: E402


def save(fig, path) -> None:
    """Save a figure atomically and close it."""
    with atomic_path(path, suffix=".png") as tmp:
        fig.savefig(tmp, dpi=110, bbox_inches="tight", format="png")
    plt.close(fig)


def plot_rollout_curves(results, path, title: str = "", noise_after: int | None = None) -> None:
    """Per-step reward and corpus residual of each episode: one colour per episode (named in
    the legend), its OOD band dashed in the same colour, flagged steps as red x markers."""
    from matplotlib.lines import Line2D

    fig, (ax_r, ax_res) = plt.subplots(2, 1, figsize=(8, 6), sharex=True)
    colours = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    handles, any_band, any_flag = [], False, False
    for i, res in enumerate(results):
        colour = colours[i % len(colours)]
        t = np.arange(res.length)
        ax_r.plot(t, res.rewards, lw=1, alpha=0.8, color=colour)
        resid = np.array([np.nan if x is None else x for x in res.residuals], dtype=float)
        ax_res.plot(t, resid, lw=1, alpha=0.8, color=colour)
        handles.append(Line2D([], [], color=colour, lw=1.5,
                              label=f"episode {getattr(res, 'episode', i)}"))
        band = np.array(getattr(getattr(res, "monitor", None), "upper", []), dtype=float)
        if len(band) == len(t):
            ax_res.plot(t, np.where(np.isfinite(band), band, np.nan), ls="--", lw=0.8,
                        color=colour, alpha=0.6)
            any_band = True
        flags = np.flatnonzero(np.asarray(res.ood, bool)[:len(t)])
        if len(flags):
            ax_res.scatter(flags, resid[flags], marker="x", color="red", s=22, zorder=3)
            any_flag = True
    if noise_after is not None:
        for ax in (ax_r, ax_res):
            ax.axvline(noise_after, color="grey", ls=":", lw=1)
    if any_band:
        handles.append(Line2D([], [], color="grey", ls="--", lw=0.8,
                              label="OOD band (3 sigma, its episode's colour)"))
    if any_flag:
        handles.append(Line2D([], [], color="red", marker="x", ls="", label="OOD flag"))
    ax_r.set_ylabel("reward")
    ax_res.set_ylabel("corpus residual")
    ax_res.set_xlabel("step")
    ax_res.legend(handles=handles, loc="upper left", fontsize=8)
    fig.suptitle(title)
    save(fig, path)


def plot_bars(labels, means, stds, path, title: str = "", ylabel: str = "") -> None:
    """A bar chart with error bars."""
    fig, ax = plt.subplots(figsize=(max(4, 0.9 * len(labels) + 2), 4))
    x = np.arange(len(labels))
    ax.bar(x, means, yerr=stds, capsize=4, color="#4c72b0")
    ax.set_xticks(x, labels, rotation=30, ha="right")
    ax.set_ylabel(ylabel)
    ax.set_title(title)
    ax.axhline(0, color="black", lw=0.6)
    save(fig, path)


def plot_rollouts(env_name: str, results, path, noise_after: int | None = None) -> None:
    """``aoc rollout --plot``: the trajectories of a built-in task that draws them (2-D
    observations), else the residual and reward curves of every episode."""
    task = TASKS.get(env_name)
    if task is not None and hasattr(task, "plot_trajectories") and \
            np.asarray(results[0].observations).shape[-1] == 2:
        paths = [np.asarray(r.observations) for r in results]
        task.plot_trajectories(paths, path, title=f"{env_name}: {len(paths)} rollouts")
    else:
        plot_rollout_curves(results, path, title=env_name, noise_after=noise_after)
