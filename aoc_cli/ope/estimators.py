"""Offline policy evaluation on a log of episodes of any length: per-decision weighted
importance sampling (PDWIS), weighted doubly robust (WDR, Thomas & Brunskill 2016), the
direct method's mean, the on-policy mean return, bootstrap intervals over episodes and the
effective sample size.

Hand-written: no library we know of does this on ragged episodes (d3rlpy has fitted Q
evaluation only, used by :mod:`aoc_cli.ope.fqe`; SCOPE-RL assumes trajectories of
one fixed length). The arithmetic is numpy on a padded (E, T) layout.

**The log.** E episodes, N steps, flat and episode-contiguous as in a corpus: ``starts``
(E + 1,) row offsets, ``rewards`` (N,) (the reward of step t, after its action), ``rho``
(N,) = pi_e(a_t | h_t) / pi_b(a_t | h_t), the ratio of the logged action's probability under
the evaluated and the behaviour policy. A deterministic policy has pi_e = 1 where its action
is the logged one and 0 elsewhere (:func:`ratios`). w_{i,t} = prod_{k <= t} rho_{i,k}.

**Ragged episodes.** The textbook per-decision estimators normalise step t's weights over all
E episodes, an ended one keeping its last weight (an absorbing state). That is consistent,
but with the reward at the end and a policy that few long episodes follow it is far off at
log sizes that matter: step t's normaliser holds the ended episodes' weights, realised well
(few factors), while its numerator needs the rare episodes that followed the policy for t
steps, realised poorly; on an icu-sepsis log of 5,000 episodes it gave 0.46 for a policy worth
0.79 (the trajectory-wise estimator: 0.785). Here each step is normalised among the episodes
*running* at t (numerator and normaliser then hold weights of the same t factors), and the
share of the policy's episodes still running at t is estimated alongside, as a product of
weighted continuation shares (Kaplan-Meier style):

    n_t   = sum_{i running at t} w_{i,t}
    c_t   = sum_{i running at t + 1} w_{i,t} / n_t          (continuation share at t)
    S_t   = prod_{k < t} c_k                                (S_0 = 1)
    PDWIS = sum_t gamma^t S_t sum_{i running at t} w_{i,t} r_{i,t} / n_t
    WDR   = mean_i v_{i,0} + sum_t gamma^t S_t sum_{i running at t} w_{i,t} delta_{i,t} / n_t
    delta_{i,t} = r_{i,t} + gamma v_{i,t+1} - q_{i,t}        (v_{i,t+1} = 0 after the end)

with q_{i,t} = Q_hat(s_t, a_t) of the logged action and v_{i,t} = sum_a pi_e(a | s_t)
Q_hat(s_t, a). When every episode has the same length, S_t = 1 and these are exactly the
textbook PDWIS and Thomas & Brunskill's WDR (written with its telescoped control variate).
Each ratio is consistent, so both are.

**Censoring.** An episode cut short (a time limit, a stay whose end the record does not hold:
``truncated``) did not end: its last step t is observed, and the episode is known to run past
it, but not how it ended. Kaplan-Meier's estimator under censoring: it counts at t, in step
t's reward mean and among those that continue (c_t = sum_{i running at t + 1 or censored at
t} w_{i,t} / n_t), and is gone from t + 1 on. WDR leaves the censored step out of step t's
mean of delta (its delta needs v_{t+1} of a state the log does not hold). A censored episode
treated as ended scores 0 for the rest of its stay: on a small MDP whose episodes a random
clock cuts (a fifth of them), 0.39 for a policy worth 0.488, censored 0.482 (PDWIS) and
0.488 (WDR) (tests/ope/test_ope_censoring.py).

**Undefined is not 0.** Where no episode the policy reaches ends within the log (PDWIS's ended
share is 0), or no first step carries weight (WDR), the estimate is undefined: NaN, for the
point estimate and for a bootstrap replicate alike; the share of undefined replicates is
reported and intervals are taken over the defined ones (:mod:`aoc_cli.ope.support` withholds
an estimator whose share is large).

**Overflow.** Products of many ratios overflow a float64; every sum over episodes here is a
ratio of sums of step t's weights, so the weights are kept as logarithms and each step's
column scaled by its largest running weight before the exponential (the same ratios, no inf).

**Beyond the log's reach.** When no running episode follows the policy past some step t*
while the estimated share still running S_{t*} is above 0 (a policy the clinicians rarely
follow for long), the log says nothing of that share. PDWIS is then taken conditional on the
episode ending by t*: divided by the ended share sum_t S_t (1 - c_t) = 1 - S_{t*} (1 when the
log follows the policy to every end; with the reward at the end it is the weighted mean
outcome over the ending times the log reaches). On an icu-sepsis log where the policy's
followers all left it by step 7, the unconditional sum gave 0.29 for a policy worth 0.78,
the conditional one 0.78. WDR leaves that share to its model (v_{i,0} holds the whole future).
The share reached, 1 - S_{t*}, is reported (:func:`diagnostics`), with the ESS of each step's
running weights and the mean first-step ratio (1 in expectation when the propensities are
right: sum_a pi_e(a | s) = 1).
Every quantity is a ratio of sums over episodes, so a bootstrap replicate (episodes drawn
with replacement: a count c_i per episode) is the same formula with the sums weighted by c:
all replicates are a few (B, E) @ (E, T) products (:func:`bootstrap`).
"""

from __future__ import annotations

from dataclasses import dataclass, field

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
    ``decided == logged``); ``propensity`` (N,) the behaviour's. A propensity of a logged
    action outside (0, 1] is refused (the log could not have held it)."""
    p = np.asarray(propensity, np.float64)
    bad = np.flatnonzero(~(p > 0) | ~(p <= 1.0))
    if len(bad):
        raise AocError(f"the behaviour propensity of logged step {int(bad[0])} is "
                       f"{float(p[bad[0]])}: a logged action's probability must be in (0, 1] "
                       f"({len(bad)} such steps)", param="propensity")
    return np.asarray(probability_of_logged, np.float64) / p


@dataclass
class Log:
    """A log for the estimators: ``starts`` (E + 1,), ``rewards`` (N,), ``gamma``,
    ``truncated`` (E,) bool (None: none; module docstring, "Censoring"). Holds the padded
    (E, T) rewards, the step masks and the discounts gamma^t (T,)."""

    starts: np.ndarray
    rewards: np.ndarray
    gamma: float = 1.0
    truncated: np.ndarray | None = None

    def __post_init__(self):
        self.starts = np.asarray(self.starts, np.int64)
        self.rewards = np.asarray(self.rewards, np.float64)
        if len(self.starts) < 2 or self.starts[0] != 0 or self.starts[-1] != len(self.rewards) \
                or np.any(np.diff(self.starts) <= 0):
            raise AocError("episode offsets must start at 0, end at the step count and increase")
        if not 0.0 < self.gamma <= 1.0:
            raise AocError(f"the OPE's gamma must be in (0, 1], got {self.gamma}")
        self.n_episodes = len(self.starts) - 1
        self.truncated = np.zeros(self.n_episodes, bool) if self.truncated is None \
            else np.asarray(self.truncated, bool).reshape(-1)
        if len(self.truncated) != self.n_episodes:
            raise AocError(f"{len(self.truncated)} truncation flags for {self.n_episodes} "
                           "episodes")
        self.R = padded(self.starts, self.rewards)                       # (E, T)
        self.mask = padded(self.starts, np.ones(len(self.rewards))) > 0  # (E, T) running
        self.next_mask = np.concatenate(                                 # running at t + 1
            [self.mask[:, 1:], np.zeros((self.n_episodes, 1), bool)], axis=1)
        self.lengths = np.diff(self.starts)
        self.censored = np.zeros_like(self.mask)                         # (E, T)
        cut = np.flatnonzero(self.truncated)
        self.censored[cut, self.lengths[cut] - 1] = True
        self.at_risk = self.mask & ~self.censored      # running, step t's outcome observed
        self.survives = self.next_mask | self.censored  # known to run past step t
        self.discount = self.gamma ** np.arange(self.R.shape[1])        # (T,)

    def returns(self) -> np.ndarray:
        """(E,) discounted return of each episode."""
        return self.R @ self.discount

    def weights(self, rho: np.ndarray) -> np.ndarray:
        """(E, T) cumulative weights w_{i,t} = prod_{k <= t} rho_{i,k}, carried forward after
        the episode's end (its ratio 1 in the absorbing state). May overflow: the estimators
        use :meth:`log_weights`."""
        return np.cumprod(padded(self.starts, self._checked(rho), fill=1.0), axis=1)

    def log_weights(self, rho: np.ndarray) -> np.ndarray:
        """(E, T) log w_{i,t} (-inf where a ratio is 0), carried forward after the end."""
        with np.errstate(divide="ignore"):
            return np.cumsum(np.log(padded(self.starts, self._checked(rho), fill=1.0)), axis=1)

    def running_weights(self, rho: np.ndarray) -> np.ndarray:
        """(E, T) the running episodes' weights, each step's column divided by its largest
        (0 after an episode's end): the ratios of the estimators, with no overflow."""
        lw = np.where(self.mask, self.log_weights(rho), -np.inf)
        top = lw.max(0)                                                  # (T,)
        with np.errstate(invalid="ignore"):
            return np.where(np.isfinite(top), np.exp(lw - np.where(np.isfinite(top), top, 0.0)),
                            0.0)

    def episode_weights(self, rho: np.ndarray) -> np.ndarray:
        """(E,) whole-trajectory weights prod_t rho_{i,t}, divided by the largest (all 0 when
        no episode follows the policy throughout)."""
        lw = self.log_weights(rho)[:, -1]
        top = lw.max()
        return np.exp(lw - top) if np.isfinite(top) else np.zeros_like(lw)

    def _checked(self, rho: np.ndarray) -> np.ndarray:
        rho = np.asarray(rho, np.float64)
        if rho.shape != self.rewards.shape:
            raise AocError(f"ratios of {rho.shape} for a log of {self.rewards.shape} steps")
        return rho


# -- the estimators as ratios of sums over episodes -------------------------------------------
# For episode counts c (B, E): n = c @ A, h = c @ A_risk, c_t = (c @ A_cont) / h, S = shifted
# cumprod of c_t, value = (c @ base) / (c @ 1) + sum_t disc_t S_t (c @ NUM)_t / n_t. c = 1
# gives the estimate, a multinomial c one bootstrap replicate.

@dataclass
class _Parts:
    """(E, T) running weights ``A`` (step t's normaliser), ``A_risk`` (those at risk of
    ending at t), their continuing part ``A_cont``, the numerator ``num``; ``base`` (E,)
    per-episode baseline (WDR's v_{i,0}) or None; ``weighted``: an importance-sampling
    estimator (undefined where no first step carries weight)."""

    A: np.ndarray
    A_risk: np.ndarray
    A_cont: np.ndarray
    num: np.ndarray
    base: np.ndarray | None = None
    conditional: bool = False
    weighted: bool = True


def _parts_pdwis(log: Log, rho: np.ndarray) -> _Parts:
    W = log.running_weights(rho)
    return _Parts(W, W, W * log.survives, W * log.R, conditional=True)


def _parts_wdr(log: Log, rho: np.ndarray, q: np.ndarray, v: np.ndarray) -> _Parts:
    W = log.running_weights(rho)
    Q = padded(log.starts, q)
    V = padded(log.starts, v)
    v_next = np.concatenate([V[:, 1:], np.zeros((V.shape[0], 1))], axis=1) * log.next_mask
    delta = (log.R + log.gamma * v_next - Q) * log.at_risk
    return _Parts(W * log.at_risk, W, W * log.survives, W * log.at_risk * delta, V[:, 0])


def _parts_mean(values: np.ndarray) -> _Parts:
    zero = np.zeros((len(values), 1))
    return _Parts(zero, zero, zero, zero, np.asarray(values, np.float64), weighted=False)


def _scan(p: _Parts, counts: np.ndarray) -> tuple:
    """(n (B, T), S (B, T), the step means (B, T), the share reached (B,)) of replicates
    ``counts`` (B, E). Past the log's reach (no running episode follows the policy) a step's
    mean is 0 and its continuation share 1: S keeps the share the log does not reach.
    ``A_risk`` holds every running episode and ``A_cont`` those known to run past t (a
    censored one did)."""
    n = counts @ p.A
    risk = counts @ p.A_risk
    with np.errstate(divide="ignore", invalid="ignore"):
        cont = np.where(risk > 0, (counts @ p.A_cont) / np.where(risk > 0, risk, 1.0), 1.0)
        mean = np.where(n > 0, (counts @ p.num) / np.where(n > 0, n, 1.0), 0.0)
    S = np.concatenate([np.ones((len(counts), 1)), np.cumprod(cont, axis=1)], axis=1)
    return n, S[:, :-1], mean, 1.0 - S[:, -1]


def _evaluate(p: _Parts, discount: np.ndarray, counts: np.ndarray) -> np.ndarray:
    """(B,) the estimator for each row of ``counts`` (B, E); NaN where it is undefined (module
    docstring)."""
    n, S, mean, reached = _scan(p, counts)
    total = (S * mean) @ discount[:p.A.shape[1]]
    if p.conditional:   # PDWIS given the end within the log's reach (module docstring)
        with np.errstate(divide="ignore", invalid="ignore"):
            total = np.where(reached > 1e-12, total / np.where(reached > 1e-12, reached, 1.0),
                             np.nan)
    if p.weighted:
        total = np.where(n[:, 0] > 0, total, np.nan)
    if p.base is not None:
        total = total + (counts @ p.base) / counts.sum(1)
    return total


def behaviour(log: Log) -> tuple:
    """The logged behaviour's own value as a :func:`bootstrap` spec: the mean return, or
    under censoring Kaplan-Meier's (PDWIS with every ratio 1: a cut stay counts while it was
    seen, not as a return of 0). Every difference from the behaviour is taken from it."""
    if log.truncated.any():
        return ("pdwis", np.ones(int(log.starts[-1])))
    return ("mean", log.returns())


def behaviour_values(log: Log, counts: np.ndarray) -> np.ndarray:
    """(B,) the behaviour's own value (:func:`behaviour`) over each row of episode counts
    ``counts`` (B, E) (a resample of the episodes, as a refit of FQE draws)."""
    kind, arg = behaviour(log)
    parts = _parts_pdwis(log, arg) if kind == "pdwis" else _parts_mean(arg)
    return _evaluate(parts, log.discount, np.asarray(counts, np.float64))


def pdwis(log: Log, rho: np.ndarray) -> float:
    """Per-decision weighted importance sampling (module docstring); NaN if undefined."""
    return float(_evaluate(_parts_pdwis(log, rho), log.discount,
                           np.ones((1, log.n_episodes)))[0])


def wdr(log: Log, rho: np.ndarray, q_logged: np.ndarray, v_state: np.ndarray) -> float:
    """Weighted doubly robust (module docstring): ``q_logged`` (N,) Q_hat(s_t, a_t),
    ``v_state`` (N,) sum_a pi_e(a | s_t) Q_hat(s_t, a); NaN if undefined."""
    return float(_evaluate(_parts_wdr(log, rho, q_logged, v_state), log.discount,
                           np.ones((1, log.n_episodes)))[0])


def ess(log: Log, rho: np.ndarray) -> float:
    """Effective sample size of the whole-trajectory weights, (sum w)^2 / sum w^2 (E for the
    behaviour policy itself, 0 when no episode agrees with the policy throughout)."""
    return _kish(log.episode_weights(rho))


def _kish(w: np.ndarray, axis=None):
    s2 = np.sum(w * w, axis=axis)
    with np.errstate(divide="ignore", invalid="ignore"):
        out = np.where(s2 > 0, np.sum(w, axis=axis) ** 2 / np.where(s2 > 0, s2, 1.0), 0.0)
    return float(out) if axis is None else out


def diagnostics(log: Log, rho: np.ndarray) -> dict:
    """What the log says of its support for the policy of ratios ``rho`` (N,): ``ess`` (the
    whole-trajectory weights'), ``ess_per_step`` (T,) (the running weights' at each step),
    ``reached`` (the estimated share of the policy's episodes whose end the log follows,
    1 - S_{t*}; module docstring), ``first_step_weight`` (the mean first-step ratio, 1 in
    expectation when the propensities are right) with its standard error."""
    p = _parts_pdwis(log, rho)
    _, _, _, reached = _scan(p, np.ones((1, log.n_episodes)))
    first = np.asarray(rho, np.float64)[log.starts[:-1]]
    return {"ess": ess(log, rho), "ess_per_step": _kish(p.A, axis=0).tolist(),
            "reached": float(reached[0]), "first_step_weight": float(first.mean()),
            "first_step_weight_se": float(first.std(ddof=1) / np.sqrt(len(first)))
            if len(first) > 1 else float("nan")}


@dataclass
class Estimate:
    """A point estimate with its bootstrap interval (percentiles ``low``, ``high`` of the
    defined replicates); ``undefined`` the share of replicates that are not (NaN point: the
    estimate itself is undefined); ``replicates`` (B,) (NaN where undefined)."""

    estimate: float
    low: float
    high: float
    undefined: float = 0.0
    replicates: np.ndarray = field(default_factory=lambda: np.empty(0), repr=False)

    def as_dict(self) -> dict:
        """{estimate, low, high}: null for NaN (JSON has no NaN)."""
        def num(x):
            return None if not np.isfinite(x) else float(x)
        return {"estimate": num(self.estimate), "low": num(self.low), "high": num(self.high)}

    @classmethod
    def of(cls, point: float, replicates: np.ndarray, level: float = LEVEL) -> Estimate:
        """The percentile interval of ``replicates`` (B,) around ``point``."""
        r = np.asarray(replicates, np.float64)
        ok = np.isfinite(r)
        alpha = (1.0 - level) / 2
        if ok.any():
            low, high = np.quantile(r[ok], alpha), np.quantile(r[ok], 1 - alpha)
        else:
            low = high = np.nan
        return cls(float(point), float(low), float(high), float(1.0 - ok.mean()), r)

    def minus(self, other: Estimate, level: float = LEVEL) -> Estimate:
        """The paired difference self - other: both from the same bootstrap draws (one
        :func:`bootstrap` call), so its interval is the percentiles of the replicates'
        differences."""
        if len(self.replicates) != len(other.replicates):
            raise ValueError("a paired difference needs the same bootstrap draws")
        return Estimate.of(self.estimate - other.estimate, self.replicates - other.replicates,
                           level)


def bootstrap(log: Log, estimators: dict, n_boot: int = N_BOOTSTRAP, level: float = LEVEL,
              seed: int = 0, block: int = 100) -> dict:
    """Point estimates and percentile intervals over episodes resampled with replacement.

    ``estimators`` name -> ("pdwis", rho) | ("wdr", rho, q_logged, v_state) | ("mean",
    per_episode_values (E,)) (the on-policy mean return, the direct method's mean V_hat(s_0)).
    Every estimator sees the same replicates (so :meth:`Estimate.minus` pairs them). Returns
    name -> :class:`Estimate`."""
    parts = {}
    for name, spec in estimators.items():
        kind = spec[0]
        if kind == "pdwis":
            parts[name] = _parts_pdwis(log, spec[1])
        elif kind == "wdr":
            parts[name] = _parts_wdr(log, *spec[1:])
        elif kind == "mean":
            if len(spec[1]) != log.n_episodes:
                raise AocError(f"{len(spec[1])} per-episode values for {log.n_episodes} "
                               "episodes")
            parts[name] = _parts_mean(spec[1])
        else:
            raise AocError(f"unknown estimator kind {kind!r}")
    rng = np.random.default_rng(seed)
    e = log.n_episodes
    reps = {name: [] for name in parts}
    for lo in range(0, n_boot, block):
        b = min(block, n_boot - lo)
        counts = rng.multinomial(e, np.full(e, 1.0 / e), size=b).astype(np.float64)
        for name, p in parts.items():
            reps[name].append(_evaluate(p, log.discount, counts))
    out = {}
    for name, p in parts.items():
        point = float(_evaluate(p, log.discount, np.ones((1, e)))[0])
        out[name] = Estimate.of(point, np.concatenate(reps[name]), level)
    return out
