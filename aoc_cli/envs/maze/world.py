"""The maze and two-gates world: the wall with its gaps, and the gymnasium environment
(aoc_cli.envs.maze describes both tasks)."""

from __future__ import annotations

from dataclasses import dataclass

import gymnasium
import numpy as np
from gymnasium import spaces

from aoc_cli.errors import AocError

SIZE = 16.0
WALL_X = 8.0
GOAL_RADIUS = 1.0
EXPERT_RADIUS = 0.5
STEP_REWARD, GOAL_REWARD = -0.1, 10.0
SPEED = (0.5, 1.0)
NOISE_STD = 0.15


@dataclass(frozen=True)
class World:
    """The square [0, size]^2 with a wall at x = ``wall_x`` open where y is in a gap."""

    gaps: tuple[tuple[float, float], ...]
    size: float = SIZE
    wall_x: float = WALL_X

    def in_gap(self, y: np.ndarray) -> np.ndarray:
        y = np.asarray(y)
        return np.any([(lo <= y) & (y <= hi) for lo, hi in self.gaps], axis=0)

    def move(self, pos: np.ndarray, action: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Positions (B, 2) and actions (B, 2) -> new positions (B, 2), rejected (B,) bool."""
        pos = np.asarray(pos, dtype=np.float64)
        target = np.clip(pos + np.clip(action, -1.0, 1.0), 0.0, self.size)
        px, py, qx, qy = pos[:, 0], pos[:, 1], target[:, 0], target[:, 1]
        w, dx = self.wall_x, qx - px
        # The segment meets the line x = w at one point (crossing or touching it) ...
        meets = ((px - w) * (qx - w) <= 0) & (dx != 0)
        frac = np.divide(w - px, dx, out=np.zeros_like(dx), where=dx != 0)
        y_cross = py + frac * (qy - py)
        blocked = meets & ~self.in_gap(y_cross)
        # ... or runs along it: both ends must lie in the same gap.
        along = (px == w) & (qx == w)
        same_gap = np.any([(lo <= py) & (py <= hi) & (lo <= qy) & (qy <= hi)
                           for lo, hi in self.gaps], axis=0)
        blocked |= along & ~same_gap
        return np.where(blocked[:, None], pos, target), blocked

    def wall_segments(self) -> list[tuple[float, float]]:
        """The closed stretches of the wall, [(y0, y1), ...]."""
        out, y = [], 0.0
        for lo, hi in sorted(self.gaps):
            if lo > y:
                out.append((y, lo))
            y = max(y, hi)
        if y < self.size:
            out.append((y, self.size))
        return out


WORLDS = {
    "maze": World(gaps=((7.25, 8.75), (14.5, 16.0))),
    "two-gates": World(gaps=((2.75, 4.25), (11.75, 13.25))),
}

#: the evaluation settings of each world: start, goal, horizon.
SETTINGS = {"maze": ((0.0, 0.0), (16.0, 0.0), 100), "two-gates": ((0.0, 8.0), (16.0, 8.0), 32)}


class MazeEnv(gymnasium.Env):
    """The continuous maze (``world="maze"``) or two-gates world; observation = position (2,).

    ``start``/``goal`` default to the world's test task; reset option ``start`` overrides the start.
    ``info``: ``success`` (goal reached this episode), ``rejected`` (the move hit the wall).
    """

    metadata = {"render_modes": []}

    def __init__(self, world: str = "maze", start=None, goal=None,
                 goal_radius: float = GOAL_RADIUS, render_mode=None):
        if world not in WORLDS:
            raise AocError(f"unknown maze world {world!r}: use one of {', '.join(WORLDS)}")
        self.world_name, self.world = world, WORLDS[world]
        default_start, default_goal, _h = SETTINGS[world]
        self.start = np.asarray(default_start if start is None else start, dtype=np.float64)
        self.goal = np.asarray(default_goal if goal is None else goal, dtype=np.float64)
        self.goal_radius = float(goal_radius)
        self.observation_space = spaces.Box(0.0, SIZE, shape=(2,), dtype=np.float32)
        self.action_space = spaces.Box(-1.0, 1.0, shape=(2,), dtype=np.float32)
        self.position = self.start.copy()

    def reset(self, *, seed=None, options=None):
        super().reset(seed=seed)
        start = (options or {}).get("start", self.start)
        self.position = np.clip(np.asarray(start, dtype=np.float64).reshape(2), 0.0, SIZE)
        return self.position.astype(np.float32), {"success": False}

    def step(self, action):
        action = np.asarray(action, dtype=np.float64).reshape(1, 2)
        new, rejected = self.world.move(self.position[None], action)
        self.position = new[0]
        reached = bool(np.linalg.norm(self.position - self.goal) <= self.goal_radius)
        reward = STEP_REWARD + (GOAL_REWARD if reached else 0.0)
        info = {"success": reached, "rejected": bool(rejected[0])}
        return self.position.astype(np.float32), reward, reached, False, info


def make(world: str = "maze", **kw) -> gymnasium.Env:
    return gymnasium.make("aoc/Maze-v0" if world == "maze" else "aoc/TwoGates-v0", **kw)
