"""Many episodes decided at once: the controller as the policy of a vectorised rollout
(:func:`aoc_cli.envs.icu_cohort.rollout_value`), each episode's last L transitions kept as the
rows of one :class:`aoc_cli.store.History`.

``policy.reset(n)`` starts n episodes; ``policy(obs (S, d_o), alive (S,), measured (S, d_o) bool
or None)`` decides the S episodes still running (``alive`` their indices among the n;
``measured`` the cells measured at the step, false where the value was held), pushes
(observation, action) into each one's history and returns (S,) int64 actions. The reward pushed
with a transition is 0: the vectorised rollouts this serves reward only a stay's last step,
which no later decision reads.
"""

from __future__ import annotations

import numpy as np

from aoc_cli.control.rule import choose, reads_support
from aoc_cli.errors import AocError
from aoc_cli.store import History
from aoc_cli.threads import one_thread


class BatchPolicy:
    """:func:`decide_batch` with per-episode histories."""

    def __init__(self, controller):
        self.controller = controller
        self.length = int(controller.model.history_length or 0)
        self.d_o = int(controller.corpus.observation_dim)
        #: what the last call read: ``likely`` (S,) rule 7's likely actions where it ran
        self.last: dict = {}
        self.reset(0)

    def reset(self, n: int) -> None:
        """Start ``n`` episodes with empty histories."""
        L = self.length
        self.obs = np.zeros((n, L, self.d_o), np.float32)
        self.act = np.zeros((n, L), np.int64)
        self.rew = np.zeros((n, L), np.float32)
        self.mask = np.zeros((n, L), bool)

    def __call__(self, observations: np.ndarray, alive: np.ndarray,
                 measured: np.ndarray | None = None) -> np.ndarray:
        obs = np.asarray(observations, np.float32).reshape(len(observations), -1)
        alive = np.asarray(alive, np.int64)
        history = (History(self.obs[alive], self.act[alive], self.rew[alive], self.mask[alive])
                   if self.length else None)
        self.last = {}
        actions = decide_batch(self.controller, obs, history, measured, record=self.last)
        if self.length:
            for arr in (self.obs, self.act, self.rew, self.mask):
                arr[alive] = np.roll(arr[alive], -1, axis=1)
            self.obs[alive, -1], self.act[alive, -1] = obs, actions
            self.rew[alive, -1], self.mask[alive, -1] = 0.0, True
        return actions


class LikelyPolicy:
    """The clinicians' likely action as rule 7 reads it (the action most of the step's
    neighbourhood took: what it keeps), as the policy of a vectorised rollout."""

    def __init__(self, controller):
        self.controller = controller

    def reset(self, n: int) -> None:
        """Nothing to keep between steps."""

    def __call__(self, observations: np.ndarray, alive: np.ndarray,
                 measured: np.ndarray | None = None) -> np.ndarray:
        obs = np.asarray(observations, np.float32).reshape(len(observations), -1)
        return self.controller.neighbourhood.at(obs, measured).likely


def decide_batch(controller, observations: np.ndarray, history: History | None = None,
                 measured: np.ndarray | None = None, record: dict | None = None) -> np.ndarray:
    """(S,) int64 the discrete actions ``controller`` decides at S steps at once (observations
    (S, d_o), ``history`` S rows, or None: an empty one; ``measured`` (S, d_o) bool their
    measured cells, or None: all): what ``controller.decide`` decides at each, with every
    action a candidate, in one belief pass and one decomposition. Value mode, discrete
    actions. ``record``, where given, receives ``likely`` (S,): rule 7's likely actions,
    where it ran."""
    ctl = controller
    if not ctl.discrete or ctl.model.mode != "value":
        raise AocError("decide_batch decides discrete actions in value mode")
    obs = np.asarray(observations, dtype=np.float32).reshape(len(observations), -1)
    s, n = len(obs), int(ctl.corpus.n_actions)
    if ctl.do_no_harm and not reads_support(ctl.config):
        # rule 7 decides from the log's rows near each step alone (control/rule.py): the
        # decomposition, which explains a decision, does not change it
        lower, likely = ctl.harm_inputs(obs, np.zeros((s, n)), None, measured)
        if record is not None:
            record["likely"] = likely
        return choose(np.zeros((s, n)), np.zeros((s, n)), ctl.config, lower=lower,
                      kept=likely)[2].astype(np.int64)
    if history is not None:
        history = type(history)(*[np.repeat(np.asarray(x), n, axis=0) for x in history])
    with one_thread():
        beliefs = ctl.model.beliefs(np.repeat(obs, n, axis=0), np.tile(np.arange(n), s),
                                    history)
        dec = ctl.index.decompose(beliefs, k=ctl.k, selection=ctl.selection)
    residual = np.asarray(dec.residual, np.float64).reshape(s, n)
    value = np.asarray(dec.value, np.float64).reshape(s, n)
    support = ctl.support(dec)[0].reshape(s, n) if reads_support(ctl.config) else None
    lower, likely = ctl.harm_inputs(obs, value, support, measured)
    if record is not None and likely is not None:
        record["likely"] = likely
    _t, _p, chosen = choose(residual, value, ctl.config, cap=ctl.residual_cap, support=support,
                            value_std=ctl.value_std, lower=lower, kept=likely)
    return chosen.astype(np.int64)
