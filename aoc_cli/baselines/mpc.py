"""Model-predictive control with a learned dynamics model, through pytorch-mppi (``bench`` extra).

The paper's "MPC" baseline (Williams et al. 2017, MPPI). A small MLP learns the corpus's
transitions and rewards from the same context AOC sees,

    f(o, a, h) = (o' - o, r) in standardised units,
    f = argmin E_{(o, a, h, r, o') in D} || f(o, a, h) - ((o' - o) / s_o, (r - mu_r) / s_r) ||^2,

and MPPI (``pytorch_mppi.MPPI``) plans with it: each step it samples action sequences around its
nominal plan, rolls them through f for ``horizon`` steps with the history context h of the
current step held fixed (the context identifies the system, which does not change within an
episode), and returns the cost-weighted first action. The running cost is the negated predicted
reward: the MPPI state carries it as an extra coordinate, ``[o, r_prev]``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from aoc_cli.baselines.common import ActionSpace, require
from aoc_cli.baselines.features import RawFeatures
from aoc_cli.errors import AocError
from aoc_cli.settings import Settings, setting
from aoc_cli.threads import thread_limits


@dataclass(frozen=True)
class MPCConfig(Settings):
    """Dynamics model and planner settings (pytorch-mppi's defaults where not stated)."""

    label = "MPC"

    hidden: int = setting(256, bounds=">= 1", help="Units of the dynamics model's layers.")
    epochs: int = setting(30, bounds=">= 1", help="Epochs of the dynamics model.")
    batch_size: int = setting(512, bounds=">= 1", help="Mini-batch rows.")
    lr: float = setting(1e-3, bounds="> 0", help="Learning rate of the dynamics model.")
    samples: int = setting(200, bounds=">= 1", help="MPPI's sampled action sequences.")
    horizon: int = setting(15, bounds=">= 1", help="MPPI's planning horizon (steps).")
    noise: float = setting(0.25, bounds="> 0",
                           help="Exploration noise std as a fraction of the action range.")
    lambda_: float = setting(1.0, bounds="> 0", help="MPPI's temperature.")
    seed: int = setting(0, help="Seed of the model and the planner.")
    threads: int = setting(2, bounds=">= 1", help="Torch threads while training.")


def _transitions(corpus) -> np.ndarray:
    """(M,) rows t whose next row t + 1 is in the same episode (the learnable transitions)."""
    n = corpus.n_rows
    last = np.zeros(n, bool)
    last[corpus.episode_starts[1:] - 1] = True
    return np.flatnonzero(~last)


def train_dynamics(corpus, history_length: int, config: MPCConfig, progress=None):
    """Fit f on ``corpus`` (module docstring) with ``config.threads`` torch threads (for the
    fit only, aoc_cli.threads); returns (net, features)."""
    if corpus.discrete:
        raise AocError("the mpc baseline needs continuous actions")
    if corpus.rewards is None:
        raise AocError(f"corpus {corpus.name!r} has no rewards: mpc needs them")
    with thread_limits(torch=max(1, int(config.threads))):
        return _fit_dynamics(corpus, history_length, config, progress)


def _fit_dynamics(corpus, history_length: int, config: MPCConfig, progress):
    import torch
    from torch import nn

    features = RawFeatures.fit(corpus, history_length, with_action=True)
    rows = _transitions(corpus)
    x_all = features.corpus_features(corpus)
    obs = np.asarray(corpus.observations, np.float64)
    d_o = obs.shape[1]
    delta = (obs[rows + 1] - obs[rows]) / features.obs_std
    rew = (np.asarray(corpus.rewards, np.float64)[rows] - features.rew_mean) / features.rew_std
    x = torch.as_tensor(x_all[rows])
    y = torch.as_tensor(np.concatenate([delta, rew[:, None]], axis=1).astype(np.float32))
    gen = torch.Generator().manual_seed(int(config.seed))
    with torch.random.fork_rng(devices=[]):
        torch.manual_seed(int(config.seed))
        net = nn.Sequential(nn.Linear(x.shape[1], config.hidden), nn.ReLU(),
                            nn.Linear(config.hidden, config.hidden), nn.ReLU(),
                            nn.Linear(config.hidden, d_o + 1))
    opt = torch.optim.Adam(net.parameters(), lr=config.lr)
    n = len(x)
    for epoch in range(int(config.epochs)):
        perm = torch.randperm(n, generator=gen)
        for i in range(0, n, config.batch_size):
            b = perm[i:i + config.batch_size]
            loss = nn.functional.mse_loss(net(x[b]), y[b])
            opt.zero_grad(set_to_none=True)
            loss.backward()
            opt.step()
        if progress is not None:
            progress(epoch + 1, int(config.epochs))
    return net.eval(), features


class MPCPolicy:
    """MPPI over the learned dynamics model (module docstring)."""

    name = "mpc"

    def __init__(self, session, env=None, seed: int = 0, config: MPCConfig | None = None,
                 model=None, progress=None):
        require("pytorch_mppi", "mpc")
        import torch

        self.torch = torch
        self.actions = ActionSpace(session, env)
        if self.actions.discrete:
            raise AocError("the mpc baseline needs continuous actions")
        self.config = config or MPCConfig(seed=seed)
        self.seed = int(seed)
        self.episodes = 0
        if model is None:
            if progress is not None:
                progress(0, self.config.epochs, f"training the mpc dynamics model on corpus "
                                                f"{session.corpus.name!r}")
            model = train_dynamics(session.corpus, session.model.history_length, self.config,
                                   progress)
        self.net, self.features = model
        f = self.features
        self.d_o = len(f.obs_mean)
        self._o_mean = torch.as_tensor(f.obs_mean, dtype=torch.float32)
        self._o_std = torch.as_tensor(f.obs_std, dtype=torch.float32)
        self._a_mean = torch.as_tensor(f.act_mean, dtype=torch.float32)
        self._a_std = torch.as_tensor(f.act_std, dtype=torch.float32)
        self.context = torch.zeros((1, 0))
        self.planner = None

    def _dynamics(self, state, action):
        """state (K, d_o + 1) [o, r_prev], action (K, d_a) -> next state (K, d_o + 1)."""
        torch = self.torch
        o = state[:, :self.d_o]
        x = torch.cat([(o - self._o_mean) / self._o_std, (action - self._a_mean) / self._a_std,
                       self.context.expand(len(o), -1)], dim=1)
        with torch.no_grad():
            out = self.net(x)
        nxt = o + out[:, :self.d_o] * self._o_std
        r = out[:, self.d_o:] * self.features.rew_std + self.features.rew_mean
        return torch.cat([nxt, r], dim=1)

    def _cost(self, state, action):
        return -state[:, -1]

    def reset(self) -> None:
        from pytorch_mppi import MPPI

        torch = self.torch
        torch.manual_seed(self.seed * 100_003 + self.episodes)
        self.episodes += 1
        span = torch.as_tensor(self.actions.high - self.actions.low, dtype=torch.float32)
        sigma = torch.diag((self.config.noise * span) ** 2)
        self.planner = MPPI(
            self._dynamics, self._cost, self.d_o + 1, sigma,
            num_samples=self.config.samples, horizon=self.config.horizon,
            lambda_=self.config.lambda_, device="cpu",
            u_min=torch.as_tensor(self.actions.low, dtype=torch.float32),
            u_max=torch.as_tensor(self.actions.high, dtype=torch.float32))

    def decide(self, observation, history):
        """The planner's action, with ``config.threads`` torch threads (as it was trained)."""
        torch = self.torch
        if self.planner is None:
            self.reset()
        ctx = self.features.context(history) if self.features.history_length else np.zeros((1, 0))
        self.context = torch.as_tensor(ctx, dtype=torch.float32)
        state = torch.as_tensor(np.append(np.asarray(observation, np.float64), 0.0),
                                dtype=torch.float32)
        with thread_limits(torch=max(1, int(self.config.threads))):
            action = self.planner.command(state)
        return self.actions.clip(action.detach().cpu().numpy())
