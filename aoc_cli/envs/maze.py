"""maze and two-gates: a continuous 16 x 16 world with a wall at x = 8 open in two gaps.

Dynamics: position p in [0, 16]^2, action a in [-1, 1]^2, ``p' = clip(p + a, 0, 16)``; a move
whose segment p -> p' touches the wall outside a gap is rejected (the agent stays). Reward: -0.1 a
step, +10 more on the step that first reaches the goal (within distance ``GOAL_RADIUS`` = 1), which
ends the episode with ``info["success"] = True`` (``False`` in every other step's info).

* **maze** -- gaps y in [7.25, 8.75] (around 8) and [14.5, 16] (at the top), width 1.5. Test task:
  (0, 0) -> (16, 0) in at most 100 steps. Four experts head straight for their goals with speed
  U(0.5, 1) a step and N(0, 0.15^2) noise on each action coordinate: pi1 (0,0)->(8,16),
  pi2 (0,0)->(8,8), pi3 (8,16)->(16,0), pi4 (8,8)->(16,0). An expert's episode ends at its own goal
  (within ``EXPERT_RADIUS`` = 0.5) or on reaching the test goal (pi3 and pi4 do that first, with the
  +10); the data's reward is the test task's. No single expert reaches (16, 0) from (0, 0).
* **two-gates** -- gates y in [2.75, 4.25] and [11.75, 13.25] (around 3.5 and 12.5). Test task:
  (0, 8) -> (16, 8) in at most 32 steps. Two behaviour policies, ``lower-gate`` and ``upper-gate``:
  left of the wall head for the point just past their gate, (8.5, gate y), then for the goal.
"""

from __future__ import annotations

from dataclasses import dataclass

import gymnasium
import numpy as np
from gymnasium import spaces

from aoc_cli.envs import render
from aoc_cli.envs.base import Episode, Progress, Task, budget, summarise, to_corpus
from aoc_cli.errors import AocError
from aoc_cli.store import box_space

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

#: maze experts: name -> (start, goal).
EXPERTS = {"pi1": ((0.0, 0.0), (8.0, 16.0)), "pi2": ((0.0, 0.0), (8.0, 8.0)),
           "pi3": ((8.0, 16.0), (16.0, 0.0)), "pi4": ((8.0, 8.0), (16.0, 0.0))}
#: two-gates behaviour policies: name -> the y of their gate.
GATE_POLICIES = {"lower-gate": 3.5, "upper-gate": 12.5}
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


# -- behaviour policies -------------------------------------------------------------------------

def targets(policy: str, pos: np.ndarray) -> np.ndarray:
    """Where ``policy`` heads from positions (B, 2): an expert's goal, or for a gate policy the
    point just past its gate while left of the wall, then the two-gates goal. (B, 2)."""
    pos = np.asarray(pos, dtype=np.float64)
    if policy in EXPERTS:
        return np.broadcast_to(np.asarray(EXPERTS[policy][1]), pos.shape)
    if policy in GATE_POLICIES:
        gate = np.array([WALL_X + 0.5, GATE_POLICIES[policy]])
        goal = np.asarray(SETTINGS["two-gates"][1])
        return np.where((pos[:, 0] < WALL_X)[:, None], gate, goal)
    raise AocError(f"unknown maze policy {policy!r}: use one of "
                   f"{', '.join(list(EXPERTS) + list(GATE_POLICIES))}")


def heading_action(pos: np.ndarray, target: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """Actions (B, 2): straight for ``target`` (B, 2) at speed U(0.5, 1), never past it, plus
    N(0, 0.15^2) noise on each coordinate, clipped to [-1, 1]."""
    delta = np.asarray(target) - pos
    dist = np.linalg.norm(delta, axis=1)
    speed = np.minimum(rng.uniform(*SPEED, len(pos)), dist)
    unit = np.divide(delta, dist[:, None], out=np.zeros_like(delta), where=dist[:, None] > 0)
    return np.clip(unit * speed[:, None] + rng.normal(0.0, NOISE_STD, pos.shape), -1.0, 1.0)


def policy_action(policies, pos: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """Actions (B, 2) of behaviour policies (one name, or one per row) at positions (B, 2)."""
    pos = np.asarray(pos, dtype=np.float64).reshape(-1, 2)
    names = np.broadcast_to(np.asarray(policies), (len(pos),))
    goal = np.empty_like(pos)
    for name in np.unique(names):
        mask = names == name
        goal[mask] = targets(str(name), pos[mask])
    return heading_action(pos, goal, rng)


def run_policies(world: str, policies: list[str], cap: int, rng: np.random.Generator,
                 on_step=None) -> list[Episode]:
    """Run one episode per entry of ``policies`` (at once) for at most ``cap`` steps."""
    w = WORLDS[world]
    _start, test_goal, _h = SETTINGS[world]
    b = len(policies)
    names = np.asarray(policies)
    if world == "maze":
        pos = np.array([EXPERTS[p][0] for p in policies], dtype=np.float64)
        own_goal, own_radius = np.array([EXPERTS[p][1] for p in policies]), EXPERT_RADIUS
    else:
        pos = np.tile(np.asarray(SETTINGS[world][0], dtype=np.float64), (b, 1))
        own_goal, own_radius = np.tile(test_goal, (b, 1)), GOAL_RADIUS
    obs = np.zeros((cap, b, 2), np.float32)
    act = np.zeros((cap, b, 2), np.float32)
    rew = np.zeros((cap, b), np.float64)
    length = np.zeros(b, np.int64)
    success = np.zeros(b, bool)
    own = np.zeros(b, bool)
    active = np.ones(b, bool)
    for t in range(cap):
        a = policy_action(names, pos, rng).astype(np.float32)
        new, _rejected = w.move(pos, a)
        reached = np.linalg.norm(new - np.asarray(test_goal), axis=1) <= GOAL_RADIUS
        obs[t], act[t] = pos, a
        rew[t] = STEP_REWARD + np.where(reached, GOAL_REWARD, 0.0)
        length[active] += 1
        success |= active & reached
        own |= active & (np.linalg.norm(new - own_goal, axis=1) <= own_radius)
        active &= ~(success | own)
        pos = new
        if on_step is not None:
            on_step(length)
        if not active.any():
            break
    done = success | own
    return [Episode(obs[:n, i], act[:n, i], rew[:n, i], bool(done[i]), {"policy": policies[i]},
                    success=bool(success[i]), goal_reached=bool(done[i]))
            for i, n in enumerate(length)]


def _collect(world: str, steps: int | None, episodes: int | None, seed: int,
             progress: Progress | None, default_episodes: int):
    steps, episodes = budget(steps, episodes, None, default_episodes)
    names = list(EXPERTS) if world == "maze" else list(GATE_POLICIES)
    cap = SETTINGS[world][2]
    rng = np.random.default_rng(seed)
    eps: list[Episode] = []
    rows = 0
    batch = episodes if episodes is not None else 64 * len(names)
    while True:
        plan = [names[(len(eps) + i) % len(names)] for i in range(batch)]
        before = rows

        def on_step(length, before=before):
            if progress is not None and steps is not None:
                progress(min(steps, before + int(length.sum())), steps)

        new = run_policies(world, plan, cap, rng, on_step)
        eps += new
        rows += sum(len(e) for e in new)
        if progress is not None and episodes is not None:
            progress(len(eps), episodes)
        if episodes is not None or rows >= steps:
            break
    source = {"kind": "collect", "task": world, "seed": int(seed), "steps": steps,
              "episodes": episodes, "policies": names}
    data = to_corpus(eps, {"policy": names}, box_space(2, 0.0, SIZE, ["x", "y"]),
                     box_space(2, -1.0, 1.0, ["dx", "dy"]), source, steps=steps)
    return data, summarise(eps, {"policy": names}, kept_rows=steps)


# -- evaluation and pictures --------------------------------------------------------------------

def make(world: str = "maze", **kw) -> gymnasium.Env:
    return gymnasium.make("aoc/Maze-v0" if world == "maze" else "aoc/TwoGates-v0", **kw)


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


def _task(world: str, gym_id: str, default_episodes: int, policies: tuple[str, ...]) -> Task:
    start, goal, horizon = SETTINGS[world]
    desc = ("continuous 16x16 maze, four experts; test (0,0) -> (16,0)" if world == "maze"
            else "wall with two gates, one policy per gate; test (0,8) -> (16,8)")
    return Task(
        name=world, gym_id=gym_id, description=desc, horizon=horizon, policies=policies,
        make_fn=lambda **kw: make(world, **kw),
        collect_fn=lambda steps=None, episodes=None, seed=0, progress=None: _collect(
            world, steps, episodes, seed, progress, default_episodes),
        plot_fn=lambda paths, out_png, title=None, labels=None: plot_world(
            world, paths, out_png, title, labels),
        trajectory_fn=trajectory, default_episodes=default_episodes, start=start, goal=goal,
        success_test=f"within {GOAL_RADIUS:g} of ({goal[0]:g}, {goal[1]:g})",
        extra={"gaps": WORLDS[world].gaps, "goal_radius": GOAL_RADIUS},
        controller={"epsilon": 0.1},
    )


TASKS = [_task("maze", "aoc/Maze-v0", 1000, tuple(EXPERTS)),
         _task("two-gates", "aoc/TwoGates-v0", 500, tuple(GATE_POLICIES))]
