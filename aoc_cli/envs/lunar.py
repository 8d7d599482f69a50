"""lunar: gymnasium's LunarLanderContinuous-v3 with its own heuristic lander as the expert.

Behaviour data: ``gymnasium.envs.box2d.lunar_lander.heuristic`` plus *persistent* Gaussian action
noise (Ornstein-Uhlenbeck, i.e. AR(1) with correlation 0.9 from one step to the next, as in
DDPG's exploration) of stationary std 0, 0.25, 0.5 and 1, clipped to [-1, 1] (the stored action
is the one sent to the environment); the four levels in turn, one episode each.

Why persistent: AOC's value v^c is the return of the behaviour policy *after* the row's action.
With independent noise the heuristic corrects a deviation at the next step, so the logged
returns barely depend on the action taken and AOC's argmax ranks noise (30k rows, 4 episodes,
seeds 100-103: AOC -80 with independent noise against its data's 185; +145 with persistent
noise against its data's 160; docs/results/lunar.md). Success (gymnasium's ``reward_threshold``): an episode
return of at least 200, reported as ``info["success"]`` at the episode's last step by
:class:`LanderSuccess` (False on every other step).
"""

from __future__ import annotations

import gymnasium
import numpy as np
from gymnasium.envs.box2d.lunar_lander import heuristic

from aoc_cli.envs import render, replay
from aoc_cli.envs.base import Episode, Progress, Task, budget, summarise, to_corpus
from aoc_cli.store import box_space

GYM_ID = "LunarLanderContinuous-v3"
HORIZON = 1000
SUCCESS_RETURN = 200.0
#: Stationary std of the behaviour's action noise, and its correlation from step to step.
NOISE_LEVELS = (0.0, 0.25, 0.5, 1.0)
NOISE_CORRELATION = 0.9
POLICIES = tuple(f"heuristic-ou{n:g}" for n in NOISE_LEVELS)


class LanderSuccess(gymnasium.Wrapper):
    """Adds ``info["success"]`` (episode return >= 200, at the last step) and
    ``info["episode_return"]`` (the return so far) to LunarLander."""

    def reset(self, **kw):
        self._return = 0.0
        obs, info = self.env.reset(**kw)
        info["success"] = False
        return obs, info

    def step(self, action):
        obs, reward, terminated, truncated, info = self.env.step(action)
        self._return += float(reward)
        info["episode_return"] = self._return
        info["success"] = bool((terminated or truncated) and self._return >= SUCCESS_RETURN)
        return obs, reward, terminated, truncated, info


def make(**kw) -> gymnasium.Env:
    """The evaluation environment: LunarLanderContinuous-v3 (1000 steps) with success info."""
    return LanderSuccess(gymnasium.make(GYM_ID, **kw))


def expert_action(env: gymnasium.Env, observation: np.ndarray,
                  deviation: np.ndarray | None = None) -> np.ndarray:
    """The heuristic lander's action (2,) plus ``deviation`` (2,), clipped to [-1, 1], float32."""
    a = np.asarray(heuristic(env.unwrapped, observation), dtype=np.float64)
    if deviation is not None:
        a = a + deviation
    return np.clip(a, -1.0, 1.0).astype(np.float32)


def run_episode(env: gymnasium.Env, policy: str, rng: np.random.Generator) -> Episode:
    """One episode of ``policy`` (a name of POLICIES); the reset seed is drawn from ``rng``.

    The deviation from the heuristic is AR(1): d_0 ~ N(0, s^2), d_{t+1} = rho d_t +
    sqrt(1 - rho^2) s e_t (e_t standard normal), so every d_t has std s (the level).
    """
    randomly = policy == "random"  # uniform actions (--behaviour replay's first episodes)
    std = 0.0 if randomly else float(policy.rsplit("ou", 1)[1])
    rho = NOISE_CORRELATION
    obs, _info = env.reset(seed=int(rng.integers(2**31 - 1)))
    deviation = std * rng.standard_normal(2)
    observations, actions, rewards = [], [], []
    while True:
        a = rng.uniform(-1.0, 1.0, 2).astype(np.float32) if randomly \
            else expert_action(env, obs, deviation)
        deviation = rho * deviation + np.sqrt(1.0 - rho**2) * std * rng.standard_normal(2)
        observations.append(obs)
        actions.append(a)
        obs, reward, terminated, truncated, info = env.step(a)
        rewards.append(reward)
        if terminated or truncated:
            break
    return Episode(np.asarray(observations, np.float32), np.asarray(actions, np.float32),
                   np.asarray(rewards, np.float64), bool(terminated), {"policy": policy},
                   success=bool(info["success"]))


def _collect(steps: int | None, episodes: int | None, seed: int, progress: Progress | None,
             behaviour: str = "mix"):
    """``behaviour`` ``mix``: the four noise levels in turn; ``replay``: an agent that starts
    random and improves, scheduled by the share of rows (or episodes) collected so far
    (aoc_cli/envs/replay.py)."""
    steps, episodes = budget(steps, episodes, 100_000, None)
    rng = np.random.default_rng(seed)
    env = make()
    eps: list[Episode] = []
    stds: list[float | None] = []
    rows = 0
    try:
        while (steps is not None and rows < steps) or (episodes is not None
                                                       and len(eps) < episodes):
            policy = POLICIES[len(eps) % len(POLICIES)]
            if behaviour == "replay":
                std = replay.noise_at(rows / steps if steps is not None
                                      else len(eps) / episodes)
                policy = "random" if std is None else f"heuristic-ou{std!r}"
                stds.append(std)
            eps.append(run_episode(env, policy, rng))
            if behaviour == "replay":
                eps[-1].tags["policy"] = replay.label(std)
            rows += len(eps[-1])
            if progress is not None and steps is not None:
                progress(min(rows, steps), steps)
            elif progress is not None:
                progress(len(eps), episodes)
    finally:
        env.close()
    space = env.observation_space
    policies = replay.POLICIES if behaviour == "replay" else POLICIES
    source = {"kind": "collect", "task": "lunar", "gym_id": GYM_ID, "seed": int(seed),
              "steps": steps, "episodes": episodes, "policies": list(policies),
              "behaviour": behaviour}
    data = to_corpus(eps, {"policy": policies},
                     box_space(8, space.low, space.high,
                               ["x", "y", "vx", "vy", "angle", "angular_velocity",
                                "left_leg", "right_leg"]),
                     box_space(2, -1.0, 1.0, ["main_engine", "side_engine"]), source,
                     steps=steps)
    if behaviour == "replay":
        kept = np.diff(data.episode_starts)
        data.columns = {**(data.columns or {}),
                        "noise_std": replay.noise_column(stds[:len(kept)], kept)}
    return data, summarise(eps, {"policy": policies}, kept_rows=steps)


def trajectory(observations: np.ndarray) -> np.ndarray:
    """(T, 8) observations -> (T, 2) lander positions (x, y; the pad is at (0, 0))."""
    return np.asarray(observations, dtype=float)[:, :2]


def plot_trajectories(paths, out_png, title=None, labels=None) -> None:
    """Lander paths in the observation's coordinates, with the landing pad."""
    paths = render.check_paths(paths, labels)
    fig, ax = render.new_axes(title or "lunar", "x (pad at 0)", "y (pad at 0)", size=(6, 4.5))
    ax.axhline(0.0, color="#999999", lw=1)
    ax.plot([-0.2, 0.2], [0, 0], color="gold", lw=6, solid_capstyle="butt", zorder=4)
    render.draw_paths(ax, paths, labels)
    ax.set_xlim(-1.0, 1.0)
    ax.set_ylim(-0.3, 1.6)
    render.save(fig, out_png)


TASKS = [Task(
    name="lunar", gym_id=GYM_ID, horizon=HORIZON, policies=POLICIES,
    description="gymnasium LunarLanderContinuous-v3, heuristic lander with action noise",
    make_fn=make,
    collect_fn=lambda steps=None, episodes=None, seed=0, progress=None, behaviour="mix":
        _collect(steps, episodes, seed, progress, behaviour),
    behaviours=replay.BEHAVIOURS,
    plot_fn=plot_trajectories, trajectory_fn=trajectory, default_steps=100_000,
    goal=(0.0, 0.0), success_test=f"episode return >= {SUCCESS_RETURN:g}",
)]
