"""Many episodes decided at once: the controller as the policy of a vectorised rollout
(:func:`aoc_cli.envs.icu_cohort.rollout_value`), each episode's last L transitions kept as the
rows of one :class:`aoc_cli.store.History`.

``policy.reset(n)`` starts n episodes; ``policy(obs (S, d_o), alive (S,))`` decides the S
episodes still running (``alive`` their indices among the n), pushes (observation, action) into
each one's history and returns (S,) int64 actions. The reward pushed with a transition is 0:
the vectorised rollouts this serves reward only a stay's last step, which no later decision
reads.
"""

from __future__ import annotations

import numpy as np

from aoc_cli.store import History


class BatchPolicy:
    """:meth:`aoc_cli.control.Controller.decide_batch` with per-episode histories."""

    def __init__(self, controller):
        self.controller = controller
        self.length = int(controller.model.history_length or 0)
        self.d_o = int(controller.corpus.observation_dim)
        self.reset(0)

    def reset(self, n: int) -> None:
        """Start ``n`` episodes with empty histories."""
        L = self.length
        self.obs = np.zeros((n, L, self.d_o), np.float32)
        self.act = np.zeros((n, L), np.int64)
        self.rew = np.zeros((n, L), np.float32)
        self.mask = np.zeros((n, L), bool)

    def __call__(self, observations: np.ndarray, alive: np.ndarray) -> np.ndarray:
        obs = np.asarray(observations, np.float32).reshape(len(observations), -1)
        alive = np.asarray(alive, np.int64)
        history = (History(self.obs[alive], self.act[alive], self.rew[alive], self.mask[alive])
                   if self.length else None)
        actions = self.controller.decide_batch(obs, history)
        if self.length:
            for arr in (self.obs, self.act, self.rew, self.mask):
                arr[alive] = np.roll(arr[alive], -1, axis=1)
            self.obs[alive, -1], self.act[alive, -1] = obs, actions
            self.rew[alive, -1], self.mask[alive, -1] = 0.0, True
        return actions
