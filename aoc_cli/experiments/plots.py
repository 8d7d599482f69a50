"""Bench figures: grouped bars with error bars (methods x settings) and the maze-adapt curves."""

from __future__ import annotations

import numpy as np

from aoc_cli.report.plots import plot_bars, plt, save


def grouped_bars(summary: list[dict], task: str, path, title: str, metric: str = "return_mean",
                 ylabel: str = "return") -> bool:
    """One group of bars per method, one bar per setting; error bars = the summary's std.
    Returns False (and writes nothing) when the task has no result."""
    recs = [r for r in summary if r["task"] == task and r.get(metric) is not None]
    if not recs:
        return False
    methods = list(dict.fromkeys(r["method"] for r in recs))
    settings = list(dict.fromkeys(r["setting"] for r in recs))
    if len(settings) == 1:
        plot_bars(methods, [r[metric] for r in recs],
                  [r.get(f"{metric}_std") or 0.0 for r in recs], path,
                  title=f"{title} ({settings[0]})", ylabel=ylabel)
        return True
    fig, ax = plt.subplots(figsize=(max(6, 1.1 * len(methods) + 2), 4.5))
    width = 0.8 / len(settings)
    x = np.arange(len(methods))
    for j, setting in enumerate(settings):
        means, stds = [], []
        for m in methods:
            r = next((r for r in recs if r["method"] == m and r["setting"] == setting), None)
            means.append(np.nan if r is None else r[metric])
            stds.append(0.0 if r is None else (r.get(f"{metric}_std") or 0.0))
        ax.bar(x + (j - (len(settings) - 1) / 2) * width, means, width, yerr=stds, capsize=3,
               label=setting)
    ax.set_xticks(x, methods, rotation=30, ha="right")
    ax.set_ylabel(ylabel)
    ax.set_title(title)
    ax.axhline(0, color="black", lw=0.6)
    ax.legend(fontsize=8)
    save(fig, path)
    return True


def setting_bars(summary: list[dict], task: str, method: str, path, title: str,
                 metric: str = "return_mean", ylabel: str = "return") -> bool:
    """Bars over the settings of one method (an ablation)."""
    recs = [r for r in summary if r["task"] == task and r["method"] == method
            and r.get(metric) is not None]
    if not recs:
        return False
    plot_bars([r["setting"] for r in recs], [r[metric] for r in recs],
              [r.get(f"{metric}_std") or 0.0 for r in recs], path, title=title, ylabel=ylabel)
    return True


def maze_adapt_curves(summary: list[dict], paper_table: dict, path) -> bool:
    """Success rate and gate shares against pi1's sampling rate, ours (solid) and the
    paper's (dashed)."""
    recs = [r for r in summary if r["method"] == "aoc" and r.get("success_rate") is not None]
    if not recs:
        return False
    rates = [float(r["setting"].split("=")[1]) for r in recs]
    fig, ax = plt.subplots(figsize=(7, 4.2))
    x = np.arange(len(rates))
    series = (("success_rate", 100.0, "success %", "tab:green", 0),
              ("upper_gate", 1.0, "upper gate", "tab:blue", 1),
              ("lower_gate", 1.0, "lower gate", "tab:orange", 2))
    for key, scale, label, color, col in series:
        ours = np.array([r[key] * scale for r in recs], dtype=float)
        err = np.array([(r.get(f"{key}_std") or 0.0) * scale for r in recs], dtype=float)
        ax.errorbar(x, ours, yerr=err, color=color, marker="o", label=f"{label} (aoc)")
        theirs = [paper_table.get(rt) for rt in rates]
        ys = [np.nan if t is None else t[col] * (100.0 if col == 0 else 1.0) for t in theirs]
        ax.plot(x, ys, color=color, ls="--", alpha=0.6, label=f"{label} (paper)")
    ax.set_xticks(x, [f"x{rt:g}" for rt in rates])
    ax.set_xlabel("re-sampling rate of pi1's trajectories")
    ax.set_ylabel("per 100 rollouts")
    ax.set_ylim(-2, 102)
    ax.legend(fontsize=8, ncol=2)
    ax.set_title("maze-adapt: success and gate choice")
    save(fig, path)
    return True
