"""Pictures of the maze and two-gates worlds: the map with paths over it."""

from __future__ import annotations

import numpy as np

from aoc_cli.envs import render
from aoc_cli.envs.maze.world import GOAL_RADIUS, SETTINGS, SIZE, WORLDS

def trajectory(observations: np.ndarray) -> np.ndarray:
    return np.asarray(observations, dtype=float)[:, :2]


def plot_world(world: str, paths, out_png, title=None, labels=None) -> None:
    """The map (walls, gaps, start, goal) with the paths (each (T, 2) positions)."""
    paths = render.check_paths(paths, labels)
    w = WORLDS[world]
    start, goal, _h = SETTINGS[world]
    fig, ax = render.new_axes(title or world, "x", "y")
    for lo, hi in w.gaps:
        ax.plot([w.wall_x, w.wall_x], [lo, hi], color="#7fbf7f", lw=6, alpha=0.5,
                solid_capstyle="butt")
    for y0, y1 in w.wall_segments():
        ax.plot([w.wall_x, w.wall_x], [y0, y1], color="black", lw=4, solid_capstyle="butt")
    ax.plot([0, SIZE, SIZE, 0, 0], [0, 0, SIZE, SIZE, 0], color="black", lw=2)
    colors = {"pi1": "#1f77b4", "pi2": "#ff7f0e", "pi3": "#2ca02c", "pi4": "#d62728",
              "lower-gate": "#ff7f0e", "upper-gate": "#1f77b4"}
    render.draw_paths(ax, paths, labels, colors)
    ax.add_patch(_circle(goal, GOAL_RADIUS, "gold"))
    ax.plot(*start, "s", color="black", ms=8, zorder=5)
    ax.plot(*goal, "*", color="gold", ms=16, mec="black", zorder=5)
    ax.set_xlim(-0.5, SIZE + 0.5)
    ax.set_ylim(-0.5, SIZE + 0.5)
    ax.set_aspect("equal")
    render.save(fig, out_png)


def _circle(center, radius, color):
    from matplotlib.patches import Circle

    return Circle(center, radius, color=color, alpha=0.35, zorder=1)
