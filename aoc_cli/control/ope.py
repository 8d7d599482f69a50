"""Offline policy evaluation on a log of episodes of any length: per-decision weighted
importance sampling (PDWIS), weighted doubly robust (WDR, Thomas & Brunskill 2016), the
direct method's mean, the on-policy mean return, bootstrap intervals over episodes and the
effective sample size.

Hand-written: no library we know of does this on ragged episodes (d3rlpy has fitted Q
evaluation only, used by :mod:`aoc_cli.control.ope_fqe`; SCOPE-RL assumes trajectories of
one fixed length). The arithmetic is numpy on a padded (E, T) layout.

**The log.** E episodes, N steps, flat and episode-contiguous as in a corpus: ``starts``
(E + 1,) row offsets, ``rewards`` (N,) (the reward of step t, after its action), ``rho``
(N,) = pi_e(a_t | h_t) / pi_b(a_t | h_t), the ratio of the logged action's probability under
the evaluated and the behaviour policy. A deterministic policy has pi_e = 1 where its action
is the logged one and 0 elsewhere (:func:`ratios`).

**Ragged episodes.** An episode that ended sits in an absorbing state: reward 0, ratio 1,
q = v = 0. Its cumulative weight w_{i,t} = prod_{k <= t} rho_{i,k} therefore carries
forward to every later step index t and stays in each step's normaliser sum_j w_{j,t}.
(Normalising step t over the episodes still running at t instead is the classic mistake: with
the reward at the end only, each step's few finishing episodes are then weighted as if they
were all, and the estimate is off by tens of percent.)

    PDWIS = sum_t gamma^t  sum_i w_{i,t} r_{i,t} / sum_i w_{i,t}
    WDR   = PDWIS - sum_t gamma^t sum_i ( w_{i,t} q_{i,t} / sum_j w_{j,t}
                                         - w_{i,t-1} v_{i,t} / sum_j w_{j,t-1} )

with w_{i,-1} = 1 (so the first normalised weight is 1 / E), q_{i,t} = Q_hat(s_t, a_t) of
the logged action and v_{i,t} = sum_a pi_e(a | s_t) Q_hat(s_t, a). Every estimator here is a
sum over t of ratios of sums over episodes, so a bootstrap replicate (episodes drawn with
replacement: a count c_i per episode) is the same formula with the sums weighted by c: all
replicates are a few (B, E) @ (E, T) products (:func:`bootstrap`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from aoc_cli.errors import AocError

#: Bootstrap replicates and the interval's level.
N_BOOTSTRAP = 1000
LEVEL = 0.95


def padded(starts: np.ndarray, values: np.ndarray, fill: float = 0.0) -> np.ndarray:
    """(E, T) of per-step ``values`` (N,), episode i's steps in row i from column 0, ``fill``
    after its end; T the longest episode."""
    starts = np.asarray(starts, np.int64)
    lengths = np.diff(starts)
    t = np.arange(len(values)) - np.repeat(starts[:-1], lengths)
    out = np.full((len(lengths), int(lengths.max())), fill, dtype=np.float64)
    out[np.repeat(np.arange(len(lengths)), lengths), t] = values
    return out


def ratios(probability_of_logged: np.ndarray, propensity: np.ndarray) -> np.ndarray:
    """(N,) rho_t = pi_e(a_t | h_t) / pi_b(a_t | h_t). ``probability_of_logged`` (N,) the
    evaluated policy's probability of each logged action (0 or 1 for a deterministic policy:
    ``decided == logged``); ``propensity`` (N,) the behaviour's. A zero or negative
    propensity of a logged action is refused (the log could not have held it)."""
    p = np.asarray(propensity, np.float64)
    bad = np.flatnonzero(~(p > 0) | ~np.isfinite(p))
    if len(bad):
        raise AocError(f"the behaviour propensity of logged step {int(bad[0])} is {float(p[bad[0]])}: "
                       "a logged action must have a probability above 0 "
                       f"({len(bad)} such steps)", param="propensity")
    return np.asarray(probability_of_logged, np.float64) / p


@dataclass
class Log:
    """A log for the estimators: ``starts`` (E + 1,), ``rewards`` (N,), ``gamma``. Holds the
    padded (E, T) rewards, the step mask and the discounts gamma^t (T,)."""

    starts: np.ndarray
    rewards: np.ndarray
    gamma: float = 1.0

    def __post_init__(self):
        self.starts = np.asarray(self.starts, np.int64)
        self.rewards = np.asarray(self.rewards, np.float64)
        if len(self.starts) < 2 or self.starts[0] != 0 or self.starts[-1] != len(self.rewards) \
                or np.any(np.diff(self.starts) <= 0):
            raise AocError("episode offsets must start at 0, end at the step count and increase")
        if not 0.0 < self.gamma <= 1.0:
            raise AocError(f"gamma must be in (0, 1], got {self.gamma}", param="gamma")
        self.n_episodes = len(self.starts) - 1
        self.R = padded(self.starts, self.rewards)                       # (E, T)
        self.mask = padded(self.starts, np.ones(len(self.rewards))) > 0  # (E, T)
        self.discount = self.gamma ** np.arange(self.R.shape[1])        # (T,)
        self.lengths = np.diff(self.starts)

    def returns(self) -> np.ndarray:
        """(E,) discounted return of each episode."""
        return self.R @ self.discount

    def weights(self, rho: np.ndarray) -> np.ndarray:
        """(E, T) cumulative weights w_{i,t} = prod_{k <= t} rho_{i,k}, carried forward after
        the episode's end (its ratio 1 in the absorbing state)."""
        rho = np.asarray(rho, np.float64)
        if rho.shape != self.rewards.shape:
            raise AocError(f"ratios of {rho.shape} for a log of {self.rewards.shape} steps")
        return np.cumprod(padded(self.starts, rho, fill=1.0), axis=1)

    def episode_weights(self, rho: np.ndarray) -> np.ndarray:
        """(E,) whole-trajectory weights prod_t rho_{i,t}."""
        return self.weights(rho)[:, -1]


# -- the estimators as sums of ratios --------------------------------------------------------
# Each is  sum_t disc_t * sum_k (c @ A_k)_t / (c @ B_k)_t  for episode counts c (E,):
# c = 1 gives the estimate, a multinomial c one bootstrap replicate.

def _terms_pdwis(log: Log, W: np.ndarray) -> list:
    return [(W * log.R, W)]


def _terms_wdr(log: Log, W: np.ndarray, q: np.ndarray, v: np.ndarray) -> list:
    Q = padded(log.starts, q) * log.mask
    V = padded(log.starts, v) * log.mask
    W_prev = np.concatenate([np.ones((W.shape[0], 1)), W[:, :-1]], axis=1)
    return [(W * (log.R - Q), W), (W_prev * V, W_prev)]


def _evaluate_terms(terms: list, discount: np.ndarray, counts: np.ndarray) -> np.ndarray:
    """(B,) the estimator for each row of ``counts`` (B, E). A step whose normaliser is 0 (no
    episode of the replicate agrees with the policy up to it) contributes 0."""
    total = np.zeros(counts.shape[0])
    for num, den in terms:
        a, b = counts @ num, counts @ den                                # (B, T)
        with np.errstate(divide="ignore", invalid="ignore"):
            part = np.where(b > 0, a / np.where(b > 0, b, 1.0), 0.0)
        total += part @ discount
    return total


def _mean_terms(values: np.ndarray) -> list:
    """A per-episode mean as a ratio term over one column."""
    return [(np.asarray(values, np.float64)[:, None], np.ones((len(values), 1)))]


def pdwis(log: Log, rho: np.ndarray) -> float:
    """Per-decision weighted importance sampling (module docstring)."""
    W = _checked_weights(log, rho)
    ones = np.ones((1, log.n_episodes))
    return float(_evaluate_terms(_terms_pdwis(log, W), log.discount, ones)[0])


def wdr(log: Log, rho: np.ndarray, q_logged: np.ndarray, v_state: np.ndarray) -> float:
    """Weighted doubly robust (module docstring): ``q_logged`` (N,) Q_hat(s_t, a_t),
    ``v_state`` (N,) sum_a pi_e(a | s_t) Q_hat(s_t, a)."""
    W = _checked_weights(log, rho)
    terms = _terms_wdr(log, W, q_logged, v_state)
    return float(_evaluate_terms(terms, log.discount, np.ones((1, log.n_episodes)))[0])


def ess(log: Log, rho: np.ndarray) -> float:
    """Effective sample size of the whole-trajectory weights, (sum w)^2 / sum w^2 (E for the
    behaviour policy itself, 0 when no episode agrees with the policy throughout)."""
    w = log.episode_weights(rho)
    s2 = float(np.sum(w * w))
    return float(np.sum(w) ** 2 / s2) if s2 > 0 else 0.0


def _checked_weights(log: Log, rho: np.ndarray) -> np.ndarray:
    W = log.weights(rho)
    if not np.any(W[:, 0] > 0):
        raise AocError("the evaluated policy never takes the logged action at an episode's "
                       "first step (every importance weight is 0): the log cannot evaluate it")
    return W


@dataclass
class Estimate:
    """A point estimate with its bootstrap interval (percentiles ``low``, ``high``)."""

    estimate: float
    low: float
    high: float

    def as_dict(self) -> dict:
        return {"estimate": self.estimate, "low": self.low, "high": self.high}


def bootstrap(log: Log, estimators: dict, n_boot: int = N_BOOTSTRAP, level: float = LEVEL,
              seed: int = 0, block: int = 100) -> dict:
    """Point estimates and percentile intervals over episodes resampled with replacement.

    ``estimators`` name -> ("pdwis", rho) | ("wdr", rho, q_logged, v_state) | ("mean",
    per_episode_values (E,)) (the on-policy mean return, the direct method's mean V_hat(s_0)).
    Every estimator sees the same replicates. Returns name -> :class:`Estimate`."""
    terms = {}
    for name, spec in estimators.items():
        kind = spec[0]
        if kind == "pdwis":
            terms[name] = (_terms_pdwis(log, _checked_weights(log, spec[1])), log.discount)
        elif kind == "wdr":
            terms[name] = (_terms_wdr(log, _checked_weights(log, spec[1]), spec[2], spec[3]),
                           log.discount)
        elif kind == "mean":
            if len(spec[1]) != log.n_episodes:
                raise AocError(f"{len(spec[1])} per-episode values for {log.n_episodes} "
                               "episodes")
            terms[name] = (_mean_terms(spec[1]), np.ones(1))
        else:
            raise AocError(f"unknown estimator kind {kind!r}")
    rng = np.random.default_rng(seed)
    e = log.n_episodes
    reps = {name: [] for name in terms}
    for lo in range(0, n_boot, block):
        b = min(block, n_boot - lo)
        counts = rng.multinomial(e, np.full(e, 1.0 / e), size=b).astype(np.float64)
        for name, (t, disc) in terms.items():
            reps[name].append(_evaluate_terms(t, disc, counts))
    alpha = (1.0 - level) / 2
    ones = np.ones((1, e))
    out = {}
    for name, (t, disc) in terms.items():
        point = float(_evaluate_terms(t, disc, ones)[0])
        r = np.concatenate(reps[name])
        out[name] = Estimate(point, float(np.quantile(r, alpha)), float(np.quantile(r, 1 - alpha)))
    return out
