"""Running a policy in an environment: the control-time history, episodes, OOD flags.

The history at control time is built exactly as in the corpus: the previous L transitions
(o, a, r) of the episode, oldest first, zero-padded at the front with a mask.
"""

from __future__ import annotations

import inspect
import time
from collections import deque
from dataclasses import dataclass, field
from typing import Protocol, runtime_checkable

import gymnasium as gym
import numpy as np

from aoc_cli.control.controller import Decision
from aoc_cli.control.monitor import OODMonitor
from aoc_cli.errors import AocError
from aoc_cli.store import History


@runtime_checkable
class Policy(Protocol):
    """What runs in an environment: the controller, or a baseline
    (:func:`aoc_cli.baselines.make_baseline`). ``decide`` returns a :class:`Decision` (its
    residual is tracked and monitored) or a plain action: a (d_a,) float array, or an int for
    a discrete space. A policy may also have ``reset()``, called at each episode start."""

    def decide(self, observation: np.ndarray, history: History): ...


class HistoryBuffer:
    """The last L transitions of the running episode, as a one-row :class:`History`."""

    def __init__(self, length: int, observation_dim: int, action_dim: int, discrete: bool):
        self.length = length
        self.d_o, self.d_a, self.discrete = observation_dim, action_dim, discrete
        self.items: deque = deque(maxlen=max(length, 1))

    def reset(self) -> None:
        self.items.clear()

    def push(self, observation, action, reward: float) -> None:
        if self.length > 0:
            self.items.append((np.asarray(observation, np.float32).reshape(-1),
                               action, float(reward)))

    def history(self) -> History:
        L = self.length
        obs = np.zeros((1, L, self.d_o), np.float32)
        act = np.zeros((1, L), np.int64) if self.discrete else np.zeros((1, L, self.d_a), np.float32)
        rew = np.zeros((1, L), np.float32)
        mask = np.zeros((1, L), bool)
        items = list(self.items)[-L:] if L else []
        for j, (o, a, r) in enumerate(items):
            slot = L - len(items) + j
            obs[0, slot], rew[0, slot], mask[0, slot] = o, r, True
            if self.discrete:
                act[0, slot] = int(a)
            else:
                act[0, slot] = np.asarray(a, np.float32).reshape(-1)
        return History(obs, act, rew, mask)


def flatten_observation(env: gym.Env, observation) -> np.ndarray:
    """A flat float32 vector (Dict/Tuple observations flattened as gymnasium does)."""
    space = env.observation_space
    if isinstance(space, (gym.spaces.Dict, gym.spaces.Tuple)):
        observation = gym.spaces.flatten(space, observation)
    return np.asarray(observation, dtype=np.float32).reshape(-1)


def action_space_of(env: gym.Env) -> dict | None:
    """The box of a gymnasium env's action space, as the controller takes it (None: discrete)."""
    space = env.action_space
    if isinstance(space, gym.spaces.Box):
        return {"type": "box", "shape": [int(np.prod(space.shape))],
                "low": np.asarray(space.low, float).reshape(-1).tolist(),
                "high": np.asarray(space.high, float).reshape(-1).tolist()}
    return None


def check_spaces(env: gym.Env, corpus) -> None:
    """The environment must have the corpus's observation and action spaces."""
    obs_dim = int(gym.spaces.flatdim(env.observation_space))
    space = env.action_space
    if obs_dim != corpus.observation_dim:
        raise AocError(f"the environment's observations have {obs_dim} dimensions, corpus "
                       f"{corpus.name!r} has {corpus.observation_dim}: use the task the corpus "
                       "was collected on")
    if corpus.discrete:
        if not isinstance(space, gym.spaces.Discrete) or int(space.n) != corpus.n_actions:
            raise AocError(f"corpus {corpus.name!r} has {corpus.n_actions} discrete actions, "
                           f"the environment's action space is {space}")
    else:
        if not isinstance(space, gym.spaces.Box) or int(np.prod(space.shape)) != corpus.action_dim:
            raise AocError(f"corpus {corpus.name!r} has {corpus.action_dim}-d continuous "
                           f"actions, the environment's action space is {space}")


def check_same_spaces(corpus, data, use: str) -> None:
    """Corpus ``data`` must have the spaces of ``corpus`` (observation and action dims, action
    type, rewards) for ``corpus``'s model to decide on its steps; ``use`` says what is refused
    (e.g. ``"explain its steps"``)."""
    mine = (corpus.observation_dim, corpus.action_dim, corpus.discrete, corpus.n_actions,
            corpus.has_rewards)
    theirs = (data.observation_dim, data.action_dim, data.discrete, data.n_actions,
              data.has_rewards)
    if mine != theirs:
        raise AocError(
            f"corpus {data.name!r} does not match {corpus.name!r} (observation dims, action "
            f"dims or type, rewards: {theirs} against {mine}): {use} with a model of its own")


@dataclass
class EpisodeResult:
    """One episode: its summary figures and per-step traces (T steps)."""

    episode: int
    seed: int
    total_return: float = 0.0
    length: int = 0
    success: bool | None = None
    observations: list = field(default_factory=list)
    rewards: list = field(default_factory=list)
    residuals: list = field(default_factory=list)
    ood: list = field(default_factory=list)
    decisions: list = field(default_factory=list)
    histories: list = field(default_factory=list)
    #: each decided step's measured cells (d_o,) bool, where the environment says
    measured: list = field(default_factory=list)
    seconds: float = 0.0
    monitor: OODMonitor | None = None
    """The OOD monitor that flagged the steps (its running band), when one was given."""

    @property
    def ood_steps(self) -> int:
        return int(np.sum(self.ood))

    @property
    def mean_residual(self) -> float | None:
        r = [x for x in self.residuals if x is not None and np.isfinite(x)]
        return float(np.mean(r)) if r else None

    def summary(self) -> dict:
        return {
            "episode": self.episode,
            "return": self.total_return,
            "length": self.length,
            "success": self.success,
            "ood_steps": self.ood_steps,
            "mean_residual": self.mean_residual,
        }


def run_episode(env: gym.Env, policy: Policy, history_length: int, corpus, episode: int, seed: int,
                monitor: OODMonitor | None = None, noise_after: int | None = None,
                noise_std: float = 0.0, keep_decisions: bool = False) -> EpisodeResult:
    """Run ``policy.decide(observation, history)`` until the episode ends; a policy whose
    ``decide`` takes ``measured`` also gets the environment's ``info["measured"]`` (the cells
    measured at the step, where the environment says).

    ``policy.decide`` returns a :class:`Decision` (residual tracked, OOD monitored) or a plain
    action. After step ``noise_after``, Gaussian noise of ``noise_std`` (a fraction of the
    action range) disturbs the applied action; the history records the applied action.
    """
    result = EpisodeResult(episode=episode, seed=seed, monitor=monitor)
    buffer = HistoryBuffer(history_length, corpus.observation_dim, corpus.action_dim,
                           corpus.discrete)
    rng = np.random.default_rng(seed + 7919)
    if hasattr(policy, "reset"):
        policy.reset()
    obs, info = env.reset(seed=seed)
    obs = flatten_observation(env, obs)
    reads = "measured" in inspect.signature(policy.decide).parameters
    start = time.perf_counter()
    done = False
    while not done:
        history = buffer.history()
        measured = info.get("measured") if reads else None
        out = (policy.decide(obs, history, measured=measured) if reads
               else policy.decide(obs, history))
        decision = out if isinstance(out, Decision) else None
        action = np.asarray(out.action if decision is not None else out)
        applied = action
        if noise_after is not None and result.length >= noise_after and not corpus.discrete:
            space = env.action_space
            span = np.asarray(space.high - space.low, dtype=np.float64)
            applied = np.clip(action + rng.standard_normal(action.shape) * noise_std * span,
                              space.low, space.high)
        env_action = int(applied) if corpus.discrete else np.asarray(applied, np.float32)
        next_obs, reward, terminated, truncated, info = env.step(env_action)
        residual = decision.residual if decision is not None else None
        flagged = monitor.update(residual) if (monitor is not None and residual is not None) \
            else False
        result.observations.append(obs)
        result.rewards.append(float(reward))
        result.residuals.append(residual)
        result.ood.append(flagged)
        if keep_decisions:
            result.decisions.append(decision)
            result.histories.append(history)
            if measured is not None:
                result.measured.append(np.asarray(measured, bool))
        buffer.push(obs, applied, float(reward))
        result.total_return += float(reward)
        result.length += 1
        obs = flatten_observation(env, next_obs)
        done = bool(terminated or truncated)
    if "success" in info:
        result.success = bool(info["success"])
    result.observations.append(obs)
    result.seconds = time.perf_counter() - start
    return result


def summarize(results: list[EpisodeResult]) -> dict:
    """``return_mean, return_std, success_rate, seconds_per_step`` over episodes."""
    returns = np.array([r.total_return for r in results], dtype=np.float64)
    successes = [r.success for r in results if r.success is not None]
    steps = sum(r.length for r in results)
    return {
        "episodes": len(results),
        "return_mean": float(returns.mean()) if len(returns) else None,
        "return_std": float(returns.std()) if len(returns) else None,
        "success_rate": float(np.mean(successes)) if successes else None,
        "ood_steps": int(sum(r.ood_steps for r in results)),
        "seconds_per_step": sum(r.seconds for r in results) / max(steps, 1),
    }
