"""``--belief critic``: the belief is the last hidden layer of an offline Q-learning critic.

The paper's reference code (``reproduce_pendulum-het.py``, ``reproduce_lunar.py``) takes the
belief of (o, a, h) from the target critic of a TD3 agent trained on the corpus: a GRU reads
the history, two fully connected layers follow, and Q is linear in the last one. aoc does the
same with the network of every other belief (:class:`~aoc_cli.belief.model.BeliefNet`: GRU,
fc1, fc2, fc3 -> belief (d_b), head -> Q), so index, rollout and explain load it unchanged.

Training (TD3+BC: Fujimoto and Gu 2021, on top of TD3: Fujimoto et al. 2018), on rows
(o_t, a_t, r_t, h_t) whose next row (o_{t+1}, h_{t+1}) is in the same episode, or that end it
with a terminal::

    y   = r_t / sigma_r + gamma (1 - terminal_t) min_{i=1,2} Q'_i(o_{t+1}, a', h_{t+1})
    a'  = clip(pi'(o_{t+1}, h_{t+1}) + clip(N(0, 0.2 s), -0.5 s, 0.5 s), low, high)
    L_Q = sum_i (Q_i(o_t, a_t, h_t) - y)^2
    L_pi = -Q_1(o_t, pi(o_t, h_t), h_t) / mean|Q_1| + w_bc (pi(o_t, h_t) - a_t)^2   (every 2nd)

with twin critics Q_1, Q_2 sharing the history GRU (as the reference code's critic does),
target networks Q', pi' updated by Polyak averaging (tau = 0.005), s the half-width of the
action box, sigma_r the reward's standard deviation and everything in the standardised units of
the encoder. ``w_bc = 0`` is plain TD3 as in the reference code. Offline, nothing keeps a plain
TD3 actor near the data, so its critic is trained on the targets of actions the corpus never
shows (extrapolation error, the reason TD3+BC exists); the default ``w_bc = 0.4`` (TD3+BC's
alpha = 2.5) keeps the bootstrapped actions near the logged ones. At the budgets measured here
the two did not differ yet (benchmarks/notes/critic_bc.py, docs/notes/belief.md). Rows that end a truncated episode have no next
observation in the corpus and are left out of the TD loss.

The belief is the target critic's Q_1 layer ``fc3`` (d_b units, the config's activation).
The linear head l that the controller and ``predict`` use maps the belief to the chosen value
v (``--value``, the return-to-go by default), **fitted by least squares on the frozen critic
features** of the training rows: v_hat stays a weighted sum of logged values and l is exactly
what the other beliefs' heads are. Q itself (its head, in reward units) is kept in the model's
config.json (``critic``) for diagnostics.
"""

from __future__ import annotations

import copy
import math
import time
from dataclasses import dataclass

import numpy as np
import torch
from torch import nn

from aoc_cli.belief.config import BeliefConfig
from aoc_cli.belief.model import BeliefNet, Encoder
from aoc_cli.errors import AocError, BadSetting, NoRewards, param

TAU = 0.005
POLICY_NOISE = 0.2      # target smoothing noise, times the action box's half-width
NOISE_CLIP = 0.5
POLICY_EVERY = 2
LR = 3e-4
#: Gradient steps between two validation records (the rows of metrics.csv).
RECORD_EVERY = 500


class TwinCritic(nn.Module):
    """Q_1 (a BeliefNet whose head is Q) and Q_2 (its own three layers and head) on one GRU."""

    def __init__(self, d_o: int, d_a_in: int, config: BeliefConfig):
        super().__init__()
        self.q1 = BeliefNet(d_o, d_a_in, 1, config.history_length, hidden=config.hidden,
                            belief_dim=config.belief_dim, use_action=True,
                            belief_activation=config.belief_activation)
        joined = self.q1.fc1.in_features
        self.q2 = nn.Sequential(nn.Linear(joined, config.hidden), nn.ReLU(),
                                nn.Linear(config.hidden, config.hidden), nn.ReLU(),
                                nn.Linear(config.hidden, config.belief_dim),
                                nn.Tanh() if config.belief_activation == "tanh" else nn.ReLU(),
                                nn.Linear(config.belief_dim, 1))

    def forward(self, obs, act, steps) -> tuple[torch.Tensor, torch.Tensor]:
        """obs (B, d_o), act (B, d_a), steps (B, L, F) -> Q_1 (B,), Q_2 (B,)."""
        memory = self.q1.memory(steps)
        q1 = self.q1.head(self.q1.belief_from_memory(memory, obs, act))[:, 0]
        parts = ([] if memory is None else [memory]) + [obs, act]
        return q1, self.q2(torch.cat(parts, dim=-1))[:, 0]

    def first(self, obs, act, steps) -> torch.Tensor:
        return self.q1(obs, act, steps)[1][:, 0]


class Actor(nn.Module):
    """pi(o, h): a BeliefNet without the action whose head gives the standardised action,
    squashed into the (standardised) action box."""

    def __init__(self, d_o: int, d_a: int, config: BeliefConfig, low: torch.Tensor,
                 high: torch.Tensor):
        super().__init__()
        self.net = BeliefNet(d_o, d_a, d_a, config.history_length, hidden=config.hidden,
                             belief_dim=config.belief_dim, use_action=False,
                             belief_activation=config.belief_activation)
        self.register_buffer("centre", (high + low) / 2)
        self.register_buffer("radius", (high - low) / 2)

    def forward(self, obs, steps) -> torch.Tensor:
        return self.centre + self.radius * torch.tanh(self.net(obs, None, steps)[1])


def action_box(corpus, encoder: Encoder) -> tuple[torch.Tensor, torch.Tensor]:
    """The action box (low, high), each (d_a,), in the encoder's standardised units: the
    space's declared bounds, else the observed range."""
    space = corpus.action_space
    acts = np.asarray(corpus.actions, dtype=np.float64).reshape(corpus.n_rows, -1)
    low = np.asarray(space.get("low", acts.min(0)), dtype=np.float64)
    high = np.asarray(space.get("high", acts.max(0)), dtype=np.float64)
    low = np.where(np.isfinite(low), low, acts.min(0))
    high = np.where(np.isfinite(high), high, acts.max(0))
    return encoder.actions(low[None])[0], encoder.actions(high[None])[0]


def transitions(corpus) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """next (N,) int64 row of each row (itself where there is none), done (N,) float32
    (terminal: no bootstrap) and usable (N,) bool (the TD target is known: the next row is in
    the episode, or the row is terminal)."""
    n = corpus.n_rows
    starts = np.asarray(corpus.episode_starts, dtype=np.int64)
    last = np.zeros(n, bool)
    last[starts[1:] - 1] = True
    terminal = np.asarray(corpus.read("terminals"), dtype=bool) & last
    nxt = np.where(last, np.arange(n), np.arange(n) + 1)
    return nxt, terminal.astype(np.float32), ~last | terminal


def td_target(reward: torch.Tensor, done: torch.Tensor, q1_next: torch.Tensor,
              q2_next: torch.Tensor, gamma: float) -> torch.Tensor:
    """The clipped double-Q target ``r + gamma (1 - done) min(Q'_1, Q'_2)`` (all (B,))."""
    return reward + gamma * (1.0 - done) * torch.minimum(q1_next, q2_next)


@dataclass
class CriticFit:
    """What :func:`fit_critic` returns: the target critic (its ``q1`` is the belief network),
    the actor, and one record per RECORD_EVERY steps."""

    critic: TwinCritic
    actor: Actor
    history: list[dict]
    reward_scale: float


def fit_critic(corpus, inputs, encoder: Encoder, config: BeliefConfig,
               train_rows: np.ndarray, val_rows: np.ndarray, device: torch.device,
               on_record=None) -> CriticFit:
    """Train the twin critic and the actor on ``train_rows`` for ``config.critic_steps`` steps.

    ``inputs`` is :func:`aoc_cli.belief.inputs.encode_corpus` of the corpus with the actions;
    ``on_record(record)`` is called with each record (every RECORD_EVERY steps).
    """
    _refuse_unsuitable(corpus)
    started = time.perf_counter()
    nxt_np, done_np, usable = transitions(corpus)
    scale = float(encoder.norm.reward_std)
    reward = torch.as_tensor(np.asarray(corpus.rewards, np.float64) / scale,
                             dtype=torch.float32, device=device)
    nxt = torch.as_tensor(nxt_np, device=device)
    done = torch.as_tensor(done_np, device=device)
    tr = torch.as_tensor(train_rows[usable[train_rows]], device=device)
    va = torch.as_tensor(val_rows[usable[val_rows]], device=device)
    if len(tr) == 0:
        raise AocError("no training row has a next row in its episode: "
                       f"{param('belief', 'critic')} needs episodes longer than one step")
    low, high = action_box(corpus, encoder)
    critic, actor, critic_t, actor_t = _networks(corpus, config, low, high, device)
    opt_q = torch.optim.Adam(critic.parameters(), lr=LR)
    opt_pi = torch.optim.Adam(actor.parameters(), lr=LR)
    generator = torch.Generator().manual_seed(config.seed)
    half = (high - low).to(device) / 2
    gamma = float(config.gamma)
    batch = int(config.batch_size)

    def td_batch(rows, net_q=critic):
        o, a, h = inputs.batch(rows)
        on, _an, hn = inputs.batch(nxt[rows])
        with torch.no_grad():
            noise = (torch.randn(a.shape, generator=generator).to(device) * POLICY_NOISE
                     * half).clamp(-NOISE_CLIP * half, NOISE_CLIP * half)
            a_next = torch.maximum(torch.minimum(actor_t(on, hn) + noise, high.to(device)),
                                   low.to(device))
            y = td_target(reward[rows], done[rows], *critic_t(on, a_next, hn), gamma)
        q1, q2 = net_q(o, a, h)
        return o, a, h, q1, q2, y

    history: list[dict] = []
    running, count = 0.0, 0
    for step in range(1, int(config.critic_steps) + 1):
        rows = tr[torch.randint(len(tr), (batch,), generator=generator).to(device)]
        o, a, h, q1, q2, y = td_batch(rows)
        loss_q = nn.functional.mse_loss(q1, y) + nn.functional.mse_loss(q2, y)
        opt_q.zero_grad(set_to_none=True)
        loss_q.backward()
        opt_q.step()
        running += float(loss_q.detach())
        count += 1
        if step % POLICY_EVERY == 0:
            _actor_step(actor, critic, opt_pi, o, a, h, config.critic_bc_weight)
            _soft_update(((critic, critic_t), (actor, actor_t)))
        if step % RECORD_EVERY == 0 or step == config.critic_steps:
            record = {"epoch": step, "train_loss": running / count,
                      **_validate(td_batch, va, critic_t, scale)}
            record["seconds"] = time.perf_counter() - started
            history.append(record)
            running, count = 0.0, 0
            if on_record is not None:
                on_record(record)
            if not math.isfinite(record["train_loss"]):
                raise AocError("the critic diverged (the TD loss is not finite): lower "
                               f"{param('lr')} or raise {param('critic_bc_weight')}")
    return CriticFit(critic_t, actor_t, history, scale)


def _networks(corpus, config: BeliefConfig, low: torch.Tensor, high: torch.Tensor,
              device: torch.device) -> tuple[TwinCritic, Actor, TwinCritic, Actor]:
    """The twin critic and the actor, seeded by ``config.seed`` (without touching the global
    generator), and their frozen target copies."""
    d_o, d_a = corpus.observation_dim, corpus.action_dim
    with torch.random.fork_rng(devices=[]):
        torch.manual_seed(config.seed)
        critic = TwinCritic(d_o, d_a, config).to(device)
        actor = Actor(d_o, d_a, config, low.to(device), high.to(device)).to(device)
    critic_t, actor_t = copy.deepcopy(critic), copy.deepcopy(actor)
    for p in list(critic_t.parameters()) + list(actor_t.parameters()):
        p.requires_grad_(False)
    return critic, actor, critic_t, actor_t


def _refuse_unsuitable(corpus) -> None:
    """The corpora a TD3 critic cannot be trained on: discrete actions, no rewards."""
    if corpus.discrete:
        raise BadSetting("belief", "critic",
                         f"{param('belief', 'critic')} needs continuous actions (its actor is a "
                         f"TD3 actor): use {param('belief', 'value')} or reward for a discrete "
                         "action space")
    if not corpus.has_rewards:
        raise NoRewards(corpus.name, "belief critic",
                        f"corpus {corpus.name!r} has no rewards: {param('belief', 'critic')} "
                        f"learns Q from them; use {param('mode', 'imitation')}")


def _actor_step(actor: Actor, critic: TwinCritic, opt_pi, o, a, h, bc_weight: float) -> None:
    """One TD3+BC actor update: maximise the first critic's Q, normalised by its mean
    magnitude, plus ``bc_weight`` times the squared distance to the logged actions (all (B, .))."""
    pi = actor(o, h)
    q = critic.first(o, pi, h)
    loss_pi = -q.mean() / q.abs().mean().detach().clamp_min(1e-6) \
        + bc_weight * ((pi - a) ** 2).mean()
    opt_pi.zero_grad(set_to_none=True)
    loss_pi.backward()
    opt_pi.step()


def _soft_update(pairs) -> None:
    """Polyak averaging of each (network, target) pair: target <- (1 - TAU) target + TAU net."""
    with torch.no_grad():
        for net, target in pairs:
            for p, pt in zip(net.parameters(), target.parameters()):
                pt.mul_(1 - TAU).add_(p, alpha=TAU)


def _validate(td_batch, va: torch.Tensor, critic_t: TwinCritic, scale: float) -> dict:
    """TD loss of the target critic on (up to 8192 of) the validation rows, and its mean Q in
    reward units (a Q that runs away from the returns shows there)."""
    rows = va[:8192]
    if len(rows) == 0:
        return {"val_loss": float("nan"), "val_q_mean": float("nan")}
    with torch.no_grad():
        _o, _a, _h, q1, q2, y = td_batch(rows, critic_t)
        loss = nn.functional.mse_loss(q1, y) + nn.functional.mse_loss(q2, y)
    return {"val_loss": float(loss), "val_q_mean": float(q1.mean()) * scale}
