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

from aoc_cli.envs.base import Task
from aoc_cli.envs.maze.collect import (EXPERTS, GATE_POLICIES, _collect, heading_action,
                                       policy_action, run_policies, targets)
from aoc_cli.envs.maze.plot import plot_world, trajectory
from aoc_cli.envs.maze.world import (EXPERT_RADIUS, GOAL_RADIUS, SETTINGS, SIZE, WALL_X, WORLDS,
                                     MazeEnv, World, make)

__all__ = ["EXPERTS", "EXPERT_RADIUS", "GATE_POLICIES", "GOAL_RADIUS", "SETTINGS", "SIZE",
           "TASKS", "WALL_X", "WORLDS", "MazeEnv", "World", "heading_action", "make",
           "plot_world", "policy_action", "run_policies", "targets", "trajectory"]


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
    )


TASKS = [_task("maze", "aoc/Maze-v0", 1000, tuple(EXPERTS)),
         _task("two-gates", "aoc/TwoGates-v0", 500, tuple(GATE_POLICIES))]
