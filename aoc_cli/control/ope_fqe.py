"""The direct method of offline policy evaluation: fitted Q evaluation by d3rlpy's
``DiscreteFQE`` (the optional ``bench`` extra), for a policy known only at the logged steps.

d3rlpy's FQE regresses Q(s_t, a_t) on r_t + gamma Q'(s_{t+1}, pi(s_{t+1})) and asks the
evaluated algorithm for pi(s_{t+1}) (``algo.impl.predict_best_action``). aoc's policies are
decisions at logged steps (they may depend on the history, and a stochastic one is a
distribution per step), so the mini-batches are drawn here (numpy, one draw of B transitions
instead of d3rlpy's per-transition sampler) and the next action of each drawn transition is
the evaluated policy's at the next logged step, handed to FQE through :class:`_NextActions`;
a stochastic policy's next action is drawn from its distribution there (an unbiased target).
The update itself is d3rlpy's (``DiscreteFQE.update``). The last step of an episode, ended or
truncated, is terminal (no bootstrap past the log).

Shapes: observations (N, d_o) float, ``policy`` (N, n) probabilities of the evaluated policy
at each logged step (one-hot for a deterministic one), actions (N,) int, rewards (N,),
``starts`` (E + 1,). :func:`fit_fqe` returns ``q`` (N, n): Q_hat(s_t, a) for every action.
"""

from __future__ import annotations

import numpy as np

from aoc_cli.errors import AocError

#: FQE settings: mini-batch, learning rate, target network sync, hidden layers.
BATCH = 256
LEARNING_RATE = 1e-3
TARGET_UPDATE = 100
HIDDEN = (64, 64)


def available() -> str | None:
    """None when d3rlpy is importable, else the one-line reason the FQE row is absent."""
    import contextlib
    import io

    try:
        # d3rlpy imports the old gym package, which prints a deprecation banner on import
        with contextlib.redirect_stderr(io.StringIO()), contextlib.redirect_stdout(io.StringIO()):
            import d3rlpy  # noqa: F401
    except ImportError:
        return "fqe: d3rlpy is not installed (pip install -e '.[bench]'), no direct method"
    return None


class _NextActions:
    """The 'algorithm' d3rlpy's FQE evaluates: it returns the next actions of the batch being
    updated (set by :func:`fit_fqe` before each update)."""

    def __init__(self):
        self.actions = None
        self.impl = self

    def predict_best_action(self, x):
        import torch

        if self.actions is None or len(self.actions) != x.shape[0]:
            raise AocError("FQE asked for next actions of a batch it was not given")
        return torch.as_tensor(self.actions, dtype=torch.long, device=x.device)


def default_steps(n_rows: int) -> int:
    """Gradient steps: about 30 passes over the log, between 1,500 and 6,000."""
    return int(np.clip(30 * n_rows // BATCH, 1500, 6000))


def fit_fqe(observations, actions, rewards, starts, policy, gamma: float = 1.0,
            steps: int | None = None, seed: int = 0, progress=None, batch: int = BATCH,
            learning_rate: float = LEARNING_RATE, target_update: int = TARGET_UPDATE
            ) -> np.ndarray:
    """Q_hat (N, n) of ``policy`` by d3rlpy's DiscreteFQE on the log (module docstring).
    Observations are standardised here (by the log's mean and spread) before d3rlpy sees
    them. ``progress(done, total)`` after each block of steps."""
    reason = available()
    if reason is not None:
        raise AocError(reason)
    # d3rlpy is the optional bench extra, torch a heavy import: both only when FQE runs
    import d3rlpy
    import torch
    from d3rlpy.dataset import TransitionMiniBatch
    from d3rlpy.models.encoders import VectorEncoderFactory
    from d3rlpy.ope import DiscreteFQE, FQEConfig

    obs = np.asarray(observations, np.float64)
    mu, sd = obs.mean(0), obs.std(0)
    x = ((obs - mu) / np.where(sd > 0, sd, 1.0)).astype(np.float32)       # (N, d_o)
    n_rows, n_actions = np.asarray(policy).shape
    act = np.asarray(actions, np.int64)
    rew = np.asarray(rewards, np.float32)
    starts = np.asarray(starts, np.int64)
    last = np.zeros(n_rows, bool)
    last[starts[1:] - 1] = True
    nxt = np.where(last, np.arange(n_rows), np.arange(n_rows) + 1)         # next logged row
    cum = np.cumsum(np.asarray(policy, np.float64), axis=1)
    cum /= cum[:, -1:]

    d3rlpy.seed(seed)
    torch.manual_seed(seed)
    algo = _NextActions()
    fqe = DiscreteFQE(algo=algo, config=FQEConfig(
        batch_size=batch, gamma=float(gamma), learning_rate=learning_rate,
        target_update_interval=target_update,
        encoder_factory=VectorEncoderFactory(hidden_units=list(HIDDEN))), device=False)
    fqe.create_impl((x.shape[1],), n_actions)
    rng = np.random.default_rng(seed)
    total = default_steps(n_rows) if steps is None else int(steps)
    one = np.ones((batch, 1), np.float32)
    for step in range(total):
        idx = rng.integers(0, n_rows, batch)
        j = nxt[idx]
        # the evaluated policy's action at the next logged step (drawn if it is stochastic)
        algo.actions = (cum[j] < rng.random((batch, 1))).sum(1).clip(0, n_actions - 1)
        fqe.update(TransitionMiniBatch(
            observations=x[idx], actions=act[idx, None].astype(np.float32),
            rewards=rew[idx, None], next_observations=x[j],
            next_actions=np.zeros((batch, 1), np.float32),
            terminals=last[idx, None].astype(np.float32), intervals=one, transitions=[]))
        if progress is not None and (step + 1) % 500 == 0:
            progress(step + 1, total)
    return q_table(fqe, x, n_actions)


def q_table(fqe, x: np.ndarray, n_actions: int, block: int = 65536) -> np.ndarray:
    """(N, n) Q_hat of every row of standardised observations ``x`` (N, d_o) and action."""
    out = np.empty((len(x), n_actions))
    rows_per = max(1, block // n_actions)
    for lo in range(0, len(x), rows_per):
        xs = x[lo:lo + rows_per]
        rep = np.repeat(xs, n_actions, axis=0)
        a = np.tile(np.arange(n_actions), len(xs))
        out[lo:lo + len(xs)] = fqe.predict_value(rep, a).reshape(len(xs), n_actions)
    return out
