"""Trajectory PNGs with matplotlib (the Agg canvas, no pyplot state), written atomically."""

from __future__ import annotations

from pathlib import Path
from typing import Sequence

import numpy as np

from aoc_cli.errors import AocError
from aoc_cli.store import atomic_path

#: Colours of labelled paths, in order of first appearance (matplotlib's tab10).
PALETTE = ["#1f77b4", "#ff7f0e", "#2ca02c", "#d62728", "#9467bd", "#8c564b", "#e377c2",
           "#7f7f7f", "#bcbd22", "#17becf"]


def new_axes(title: str | None, xlabel: str, ylabel: str, size=(5.0, 5.0)):
    """A fresh (figure, axes) pair on the Agg canvas."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=size, dpi=100)
    FigureCanvasAgg(fig)
    ax = fig.add_subplot(1, 1, 1)
    if title:
        ax.set_title(title)
    ax.set_xlabel(xlabel)
    ax.set_ylabel(ylabel)
    return fig, ax


def check_paths(paths: Sequence[np.ndarray], labels: Sequence[str] | None) -> list[np.ndarray]:
    """Each path as a float (T, 2) array; ``labels`` (if any) one per path."""
    out = []
    for i, p in enumerate(paths):
        p = np.asarray(p, dtype=float)
        if p.ndim != 2 or p.shape[1] != 2:
            raise AocError(f"trajectory {i} must be (T, 2) positions, got shape {p.shape}")
        out.append(p)
    if labels is not None and len(labels) != len(out):
        raise AocError(f"{len(labels)} labels for {len(out)} trajectories: give one per path")
    return out


def draw_paths(ax, paths: list[np.ndarray], labels: Sequence[str] | None,
               colors: dict[str, str] | None = None, alpha: float | None = None) -> None:
    """Lines for the paths, coloured by label (one legend entry per label)."""
    colors = dict(colors or {})
    alpha = alpha if alpha is not None else (0.35 if len(paths) > 20 else 0.9)
    seen: set[str] = set()
    for i, p in enumerate(paths):
        label = None if labels is None else str(labels[i])
        if label is not None and label not in colors:
            colors[label] = PALETTE[len(colors) % len(PALETTE)]
        color = colors.get(label, "#5b2c83") if label is not None else "#5b2c83"
        legend = label if label is not None and label not in seen else None
        if label is not None:
            seen.add(label)
        ax.plot(p[:, 0], p[:, 1], "-", color=color, lw=1.0, alpha=alpha, label=legend)
        if len(p):
            ax.plot(p[-1, 0], p[-1, 1], ".", color=color, ms=3, alpha=alpha)
    if seen:
        leg = ax.legend(loc="best", fontsize=8)
        for line in leg.get_lines():
            line.set_alpha(1.0)


def save(fig, out_png) -> Path:
    """Write the figure as a PNG, atomically."""
    out_png = Path(out_png)
    fig.tight_layout()
    with atomic_path(out_png, suffix=".png") as tmp:
        fig.savefig(tmp, format="png")
    return out_png


def step_series(name: str, ylabel: str, column: int):
    """``(plot, trajectory)`` of a task whose trajectory is one observation feature over the
    steps of an episode (ward: SpO2, icu-sepsis: SOFA): ``trajectory(observations (T, d_o))``
    is the (T, 2) array of (step, feature), ``plot(paths, out_png, title, labels)`` draws such
    paths; a task's ``plot_fn`` and ``trajectory_fn``."""

    def plot(paths, out_png, title=None, labels=None) -> None:
        paths = check_paths(paths, labels)
        fig, ax = new_axes(title or name, "step", ylabel)
        draw_paths(ax, paths, labels)
        save(fig, out_png)

    def trajectory(observations: np.ndarray) -> np.ndarray:
        obs = np.asarray(observations, dtype=float)
        return np.stack([np.arange(len(obs), dtype=float), obs[:, column]], axis=1)

    return plot, trajectory
