"""The behaviour policies of the maze and two-gates worlds, and the collection of their
episodes into a corpus (aoc_cli.envs.maze describes them)."""

from __future__ import annotations

import numpy as np

from aoc_cli.envs.base import Episode, Progress, budget, summarise, to_corpus
from aoc_cli.envs.maze.world import (EXPERT_RADIUS, GOAL_RADIUS, GOAL_REWARD, NOISE_STD, SETTINGS,
                                     SIZE, SPEED, STEP_REWARD, WALL_X, WORLDS)
from aoc_cli.errors import AocError
from aoc_cli.store import box_space

#: maze experts: name -> (start, goal).
EXPERTS = {"pi1": ((0.0, 0.0), (8.0, 16.0)), "pi2": ((0.0, 0.0), (8.0, 8.0)),
           "pi3": ((8.0, 16.0), (16.0, 0.0)), "pi4": ((8.0, 8.0), (16.0, 0.0))}
#: two-gates behaviour policies: name -> the y of their gate.
GATE_POLICIES = {"lower-gate": 3.5, "upper-gate": 12.5}


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
