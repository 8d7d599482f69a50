"""pendulum-het: gymnasium's Pendulum in a *normal* or a *converse* system.

The converse system applies the negated torque: the policy commands ``u`` (what is observed and
stored), the pendulum receives ``-u``. Which system produced a row is not observed (a ``system``
tag for analysis only), so a controller must tell the systems apart from the history.

Physics (gymnasium ``Pendulum-v1``; dt = 0.05, g = 10, m = l = 1, |u| <= 2, |theta_dot| <= 8)::

    u'          = clip(s * u, -2, 2)              s = +1 normal, -1 converse
    theta_dot'  = clip(theta_dot + (3 g / (2 l) sin(theta) + 3 / (m l^2) u') dt, -8, 8)
    theta'      = theta + theta_dot' dt
    r           = -(angle_normalize(theta)^2 + 0.1 theta_dot^2 + 0.001 u'^2)

Behaviour policies (per system, each good in its own system): energy-based swing-up
``u = clip(k_E theta_dot (E* - E))`` with ``E = theta_dot^2 / 2 + 15 (cos theta - 1)``, ``E* = 0``,
switching to LQR balancing ``u = -K [theta, theta_dot]`` (discrete Riccati on the linearised
system with the reward's weights Q = diag(1, 0.1), R = 0.001) when ``|theta| < 0.8``; the
commanded torque is ``s`` times that. Run with Gaussian action noise of std 0, 0.2, 0.5 and 1,
plus uniformly random torques: five policies in equal shares, half of the rows from each system.
"""

from __future__ import annotations

from functools import lru_cache

import gymnasium
import numpy as np
from gymnasium.envs.classic_control.pendulum import PendulumEnv, angle_normalize

from aoc_cli.envs import render, replay
from aoc_cli.envs.base import Episode, Progress, Task, budget, summarise, to_corpus
from aoc_cli.errors import AocError
from aoc_cli.store import box_space

SYSTEMS = ("normal", "converse")
HORIZON = 200
MAX_TORQUE = 2.0
MAX_SPEED = 8.0
DT, G, M, L = 0.05, 10.0, 1.0, 1.0
#: Gaussian action-noise levels (std of the torque noise) of the swing-up controller.
NOISE_LEVELS = (0.0, 0.2, 0.5, 1.0)
POLICIES = tuple(f"swingup-noise{n:g}" for n in NOISE_LEVELS) + ("random",)
#: Energy gain and the |theta| below which the LQR balancer takes over.
ENERGY_GAIN, BALANCE_ANGLE = 0.3, 0.8


def system_sign(system: str) -> int:
    if system not in SYSTEMS:
        raise AocError(f"unknown pendulum system {system!r}: use one of {', '.join(SYSTEMS)}")
    return 1 if system == "normal" else -1


class PendulumHetEnv(PendulumEnv):
    """Gymnasium's PendulumEnv in the ``normal`` or ``converse`` system.

    ``upright=True`` starts exactly upright at rest (reset options ``x_init = y_init = 0``);
    otherwise gymnasium's random start (angle U(-pi, pi), velocity U(-1, 1)). Reset options may
    also set ``system``. ``info["system"]`` names the system (for analysis; not observed).
    """

    def __init__(self, render_mode: str | None = None, g: float = G, system: str = "normal",
                 upright: bool = False):
        super().__init__(render_mode=render_mode, g=g)
        system_sign(system)
        self.system = system
        self.upright = bool(upright)

    def reset(self, *, seed: int | None = None, options: dict | None = None):
        options = dict(options or {})
        if "system" in options:
            system_sign(options["system"])
            self.system = options.pop("system")
        if self.upright:
            options.setdefault("x_init", 0.0)
            options.setdefault("y_init", 0.0)
        obs, info = super().reset(seed=seed, options=options or None)
        info["system"] = self.system
        return obs, info

    def step(self, u):
        u = np.asarray(u)
        applied = u if self.system == "normal" else -u
        obs, reward, terminated, truncated, info = super().step(applied)
        info["system"] = self.system
        return obs, reward, terminated, truncated, info


# -- the same physics, vectorised over pendulums ----------------------------------------------

def pendulum_step(theta: np.ndarray, theta_dot: np.ndarray, torque: np.ndarray):
    """Step B pendulums at once with exactly gymnasium's equations (and float types).

    theta, theta_dot (B,) float64; torque (B,) float32, the *applied* torque.
    Returns theta' (B,), theta_dot' (B,), reward (B,), all float64.
    """
    u = np.clip(torque, -MAX_TORQUE, MAX_TORQUE)
    costs = _square(angle_normalize(theta)) + 0.1 * _square(theta_dot) + 0.001 * _square(u)
    new_theta_dot = theta_dot + (3 * G / (2 * L) * np.sin(theta) + 3.0 / (M * L**2) * u) * DT
    new_theta_dot = np.clip(new_theta_dot, -MAX_SPEED, MAX_SPEED)
    return theta + new_theta_dot * DT, new_theta_dot, -costs


def _square(x: np.ndarray) -> np.ndarray:
    """``x ** 2`` as gymnasium's scalar code computes it: C ``pow`` (numpy's ``array ** 2``
    multiplies instead, which differs in the last bit now and then)."""
    return np.power(x, np.full_like(x, 2))


def observe(theta: np.ndarray, theta_dot: np.ndarray) -> np.ndarray:
    """(B,) states -> (B, 3) float32 observations [cos theta, sin theta, theta_dot]."""
    return np.stack([np.cos(theta), np.sin(theta), theta_dot], axis=1).astype(np.float32)


@lru_cache(maxsize=1)
def lqr_gain() -> np.ndarray:
    """(2,) LQR gain of the discretised upright linearisation, Q = diag(1, 0.1), R = 0.001."""
    import scipy.linalg

    a = np.array([[1 + 1.5 * G / L * DT**2, DT], [1.5 * G / L * DT, 1.0]])
    b = np.array([[3.0 / (M * L**2) * DT**2], [3.0 / (M * L**2) * DT]])
    q, r = np.diag([1.0, 0.1]), np.array([[0.001]])
    p = scipy.linalg.solve_discrete_are(a, b, q, r)
    return np.linalg.solve(r + b.T @ p @ b, b.T @ p @ a)[0]


def swingup_action(observations: np.ndarray, system: str | np.ndarray = "normal") -> np.ndarray:
    """The commanded torque (B,) of the swing-up + LQR controller, good in ``system``.

    observations (B, 3); ``system`` one name or a (B,) array of names / signs (+1 / -1).
    """
    obs = np.asarray(observations, dtype=np.float64).reshape(-1, 3)
    theta, theta_dot = np.arctan2(obs[:, 1], obs[:, 0]), obs[:, 2]
    energy = 0.5 * theta_dot**2 + 1.5 * G / L * (np.cos(theta) - 1.0)
    pump = np.clip(ENERGY_GAIN * theta_dot * (0.0 - energy), -MAX_TORQUE, MAX_TORQUE)
    k = lqr_gain()
    balance = np.clip(-(k[0] * theta + k[1] * theta_dot), -MAX_TORQUE, MAX_TORQUE)
    u = np.where(np.abs(theta) < BALANCE_ANGLE, balance, pump)
    if isinstance(system, str):
        sign = system_sign(system)
    else:
        system = np.asarray(system)
        sign = np.where(system == "converse", -1, 1) if system.dtype.kind in "US" else system
    return sign * u


def rollout_batch(policies: list[str], systems: list[str], lengths: np.ndarray, upright: bool,
                  rng: np.random.Generator, progress: Progress | None = None,
                  done_before: int = 0, total: int = 0) -> list[Episode]:
    """Run B episodes at once; episode b uses ``policies[b]`` in ``systems[b]`` for
    ``lengths[b]`` steps (fewer than the horizon: an episode cut short by the row budget).
    Returns the episodes in the given order."""
    b = len(policies)
    horizon = int(max(lengths))
    if upright:
        theta, theta_dot = np.zeros(b), np.zeros(b)
    else:
        theta = rng.uniform(-np.pi, np.pi, b)
        theta_dot = rng.uniform(-1.0, 1.0, b)
    sign = np.array([system_sign(s) for s in systems], dtype=np.float32)
    is_random = np.array([p == "random" for p in policies])
    noise = np.array([0.0 if p == "random" else float(p.rsplit("noise", 1)[1])
                      for p in policies])
    obs_all = np.empty((horizon, b, 3), np.float32)
    act_all = np.empty((horizon, b), np.float32)
    rew_all = np.empty((horizon, b), np.float64)
    for t in range(horizon):
        obs = observe(theta, theta_dot)
        u = swingup_action(obs, sign) + noise * rng.standard_normal(b)
        u = np.where(is_random, rng.uniform(-MAX_TORQUE, MAX_TORQUE, b), u)
        u = np.clip(u, -MAX_TORQUE, MAX_TORQUE).astype(np.float32)  # the commanded torque
        theta, theta_dot, reward = pendulum_step(theta, theta_dot, sign * u)
        obs_all[t], act_all[t], rew_all[t] = obs, u, reward
        if progress is not None:
            progress(min(total, done_before + int(np.minimum(lengths, t + 1).sum())), total)
    return [Episode(obs_all[:n, i], act_all[:n, i, None], rew_all[:n, i], False,
                    {"system": systems[i], "policy": policies[i]}, complete=bool(n == HORIZON))
            for i, n in enumerate(lengths)]


def _collect(steps: int | None, episodes: int | None, seed: int, progress: Progress | None,
             upright: bool, task_name: str, behaviour: str = "mix"):
    """The task's data: ``behaviour`` ``mix`` (the five policies in turn) or ``replay`` (per
    system, an agent that starts random and improves: aoc_cli/envs/replay.py)."""
    steps, episodes = budget(steps, episodes, 100_000, None)
    plans = []  # per system: episode lengths
    for k, system in enumerate(SYSTEMS):
        if steps is not None:
            rows = steps - steps // 2 if k == 0 else steps // 2
            full, rest = divmod(rows, HORIZON)
            lengths = [HORIZON] * full + ([rest] if rest else [])
        else:
            n = episodes - episodes // 2 if k == 0 else episodes // 2
            lengths = [HORIZON] * n
        plans.append(lengths)
    # Interleave the systems (normal, converse, normal, ...); policies cycle within a system.
    # With --behaviour replay, episode j of a system runs at noise_at(j / its episodes).
    order, stds = [], []
    for j in range(max(len(p) for p in plans)):
        for k, system in enumerate(SYSTEMS):
            if j < len(plans[k]):
                policy = POLICIES[j % len(POLICIES)]
                if behaviour == "replay":
                    std = replay.noise_at(j / len(plans[k]))
                    policy = "random" if std is None else f"swingup-noise{std!r}"
                    stds.append(std)
                order.append((system, policy, plans[k][j]))
    lengths = np.array([n for _s, _p, n in order], dtype=np.int64)
    rng = np.random.default_rng(seed)
    eps = rollout_batch([p for _s, p, _n in order], [s for s, _p, _n in order], lengths,
                        upright, rng, progress, 0, int(lengths.sum()))
    policies = POLICIES
    if behaviour == "replay":
        policies = replay.POLICIES
        for ep, std in zip(eps, stds):
            ep.tags["policy"] = replay.label(std)
    data = to_corpus(
        eps, {"system": SYSTEMS, "policy": policies},
        observation_space=box_space(3, [-1, -1, -MAX_SPEED], [1, 1, MAX_SPEED],
                                    ["cos_theta", "sin_theta", "theta_dot"]),
        action_space=box_space(1, -MAX_TORQUE, MAX_TORQUE, ["torque"]),
        source={"kind": "collect", "task": task_name, "seed": int(seed), "steps": steps,
                "episodes": episodes, "policies": list(policies), "systems": list(SYSTEMS),
                "behaviour": behaviour},
    )
    if behaviour == "replay":
        data.columns = {**(data.columns or {}), "noise_std": replay.noise_column(stds, lengths)}
    summary = summarise(eps, {"system": SYSTEMS, "policy": policies})
    return data, summary


def make(upright: bool = False, **kw) -> gymnasium.Env:
    """The evaluation environment: the normal system (``system="converse"`` to change)."""
    kw.setdefault("system", "normal")
    return gymnasium.make("aoc/PendulumHetUpright-v0" if upright else "aoc/PendulumHet-v0", **kw)


def trajectory(observations: np.ndarray) -> np.ndarray:
    """(T, 3) observations -> (T, 2) phase-plane path (theta, theta_dot)."""
    obs = np.asarray(observations, dtype=float)
    return np.stack([np.arctan2(obs[:, 1], obs[:, 0]), obs[:, 2]], axis=1)


def plot_trajectories(paths, out_png, title=None, labels=None) -> None:
    """Phase-plane portrait: theta (0 = upright) against theta_dot; the target at (0, 0)."""
    paths = render.check_paths(paths, labels)
    fig, ax = render.new_axes(title or "pendulum-het", "theta (rad, 0 = upright)",
                              "theta_dot (rad/s)")
    broken = []
    for p in paths:  # break the line where theta wraps around +-pi
        jumps = np.flatnonzero(np.abs(np.diff(p[:, 0])) > np.pi) + 1
        broken.append(np.insert(p, jumps, np.nan, axis=0))
    render.draw_paths(ax, broken, labels)
    ax.plot([0], [0], "*", color="gold", ms=14, mec="black", zorder=5)
    ax.set_xlim(-np.pi, np.pi)
    ax.set_ylim(-MAX_SPEED, MAX_SPEED)
    render.save(fig, out_png)


def _task(name: str, gym_id: str, upright: bool) -> Task:
    start = "upright at rest" if upright else "random angle and velocity"
    return Task(
        name=name, gym_id=gym_id, horizon=HORIZON, policies=POLICIES,
        description=f"Pendulum, normal or converse (negated) torque; start {start}",
        make_fn=lambda **kw: make(upright=upright, **kw),
        collect_fn=lambda steps=None, episodes=None, seed=0, progress=None, behaviour="mix":
            _collect(steps, episodes, seed, progress, upright, name, behaviour),
        behaviours=replay.BEHAVIOURS,
        plot_fn=plot_trajectories, trajectory_fn=trajectory,
        default_steps=100_000, start=(0.0, 0.0) if upright else None, goal=(0.0, 0.0),
        extra={"systems": SYSTEMS, "evaluation_system": "normal"},
    )


TASKS = [_task("pendulum-het", "aoc/PendulumHet-v0", False),
         _task("pendulum-het-upright", "aoc/PendulumHetUpright-v0", True)]
