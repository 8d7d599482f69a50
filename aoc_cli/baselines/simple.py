"""Trivial policies that expose trivial tasks: the neutral action, and uniform random actions."""

from __future__ import annotations

import numpy as np

from aoc_cli.baselines.common import ActionSpace


class ZeroPolicy:
    """Always the neutral action (see :meth:`ActionSpace.neutral`): "do nothing".

    On the upright pendulum this scores about 0, the best possible return, which is why aoc
    evaluates pendulum-het from a random start by default.
    """

    name = "zero"

    def __init__(self, session, env=None, seed: int = 0):
        self.actions = ActionSpace(session, env)

    def decide(self, observation, history):
        return self.actions.clip(self.actions.neutral())


class RandomPolicy:
    """A uniform random action each step (seeded per episode by ``reset``)."""

    name = "random"

    def __init__(self, session, env=None, seed: int = 0):
        self.actions = ActionSpace(session, env)
        self.seed = int(seed)
        self.episodes = 0
        self.rng = np.random.default_rng(seed)

    def reset(self) -> None:
        self.rng = np.random.default_rng([self.seed, self.episodes])
        self.episodes += 1

    def decide(self, observation, history):
        return self.actions.clip(self.actions.uniform(self.rng, 1)[0])
