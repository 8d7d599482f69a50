"""The log's evidence near an observation, without exact repeats: rule 2 for continuous
observations and the clinicians' likely action that rule 7 keeps (docs/design.md, "Settings
from the log's evidence").

A cohort's rows are noisy measurements: no two rows repeat, so "the (state, action) the log
took n times" has no meaning. Its continuous form is the **neighbourhood** of an observation
o: the :data:`NEAREST` logged rows nearest to o, the observations standardised by the log's
own spread (each column less its mean, over its sd), searched exactly (FAISS, flat L2); on a
log with filled gaps (``measured``: the cells that are not the corpus's imputed ones) by the
mean squared difference over the cells both rows measured (:mod:`.masked`; a query's measured
cells given with it, else all of them). From them, for every discrete action a:

* ``episodes[a]``: the distinct episodes among those rows that took a, the number of patients
  behind a's value at o (on a log whose states repeat, the rows at distance 0 are the state's
  own: the count is the exact-repeat support, up to :data:`NEAREST`);
* ``likely``: the action most of those rows took, the clinicians' likely action at o (their
  modal action where states repeat);

and once for the log, ``noise``: the sd of a row's value about the mean value of the rows of
the same neighbourhood and action (pooled over a sample of :data:`NOISE_QUERIES` rows' own
neighbourhoods, each (neighbourhood, action) group with two rows or more), the spread of one
patient's value where the log cannot tell states apart.

The **values** the rule reads are the behaviour's Q by fitted Q evaluation over the
neighbourhoods (:func:`neighbourhood_values`, computed once by ``aoc train``): a row's value
is its reward plus gamma times the mean value of the rows nearest its next observation, to
convergence. A network's Q learns little from noisy features (validation R^2 0.01 with
returns, 0.10 with FQE on the 10k cohort at noise 0.3); the mean over the rows of a
neighbourhood is what the log itself says there.

The rule (:func:`aoc_cli.control.rule.choose`, ``lower``, ``kept``): each action's lower
bound is mean(a) - z_K noise / sqrt(episodes[a]), mean(a) the mean value of the
neighbourhood's rows that took a (z_K the simultaneous one-sided 95% bound over the step's K
actions, Bonferroni; no episode: no bound, -inf); the action of the highest bound is taken
only where it beats the clinicians' likely action's own bound; otherwise the likely action is
kept (Pi_b-SPIBB's principle: leave the behaviour where the log cannot show better). Rule 2
of the exact-repeat log, with the neighbourhood in place of the state.

Shapes: observations (N, d_o), actions (N,) int, row_episode (N,) int, values (N,) float64,
measured (N, d_o) bool or None, scale (d_o,) float or None (each column's unit in place of its
sd over the log); ``at(obs (S, d_o), measured (S, d_o) or None)`` ->
:class:`Near` with episodes (S, n) int64, likely (S,) int64, rows (S, m) int64.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from statistics import NormalDist

import numpy as np

from aoc_cli.index.search.masked import MaskedIndex

#: Rows in an observation's neighbourhood.
NEAREST = 100
#: Rows whose neighbourhoods measure the noise (a seeded sample of the log).
NOISE_QUERIES = 2000
#: The bound's confidence, over the K actions of a step at once.
LEVEL = 0.95
#: Queries searched at once.
_BLOCK = 4096


def lower_bound_z(n_actions: int, level: float = LEVEL) -> float:
    """z_K = Phi^-1(1 - (1 - level) / K) (Bonferroni over the K actions of a step)."""
    return float(NormalDist().inv_cdf(1.0 - (1.0 - level) / max(int(n_actions), 1)))


@dataclass(frozen=True)
class Near:
    """The neighbourhoods of S observations: ``episodes`` (S, n) distinct episodes per
    action, ``likely`` (S,) the action most rows took (ties: the lowest), ``rows`` (S, m)
    the rows, nearest first, ``mean`` (S, n) their mean value per action."""

    episodes: np.ndarray
    likely: np.ndarray
    rows: np.ndarray
    #: (S, n) the mean value of the rows that took each action (NaN: none; or no values)
    mean: np.ndarray | None = None


class Neighbourhood:
    """The logged rows near an observation (module docstring)."""

    def __init__(self, observations: np.ndarray, actions: np.ndarray, row_episode: np.ndarray,
                 n_actions: int, values: np.ndarray | None = None, nearest: int = NEAREST,
                 seed: int = 0, noise: float | None = None,
                 measured: np.ndarray | None = None, scale: np.ndarray | None = None):
        import faiss  # lazy: FAISS only where a controller decides with the rule

        obs = np.asarray(observations, np.float64).reshape(len(observations), -1)
        self.mean = obs.mean(0)
        sd = obs.std(0) if scale is None else np.asarray(scale, np.float64).reshape(-1)
        self.scale = np.where(sd > 1e-12, sd, 1.0)
        self.actions = np.asarray(actions, np.int64)
        self.row_episode = np.asarray(row_episode, np.int64)
        self.n_actions = int(n_actions)
        self.nearest = int(min(nearest, len(obs)))
        #: the masked index where the log has filled cells (:mod:`.masked`), else None
        self.masked = None
        self.index = None
        if measured is not None and not np.all(measured):
            self.masked = MaskedIndex(self._standard(obs), measured, seed=seed)
        else:
            self.index = faiss.IndexFlatL2(obs.shape[1])
            self.index.add(self._standard(obs))
        self.z = lower_bound_z(self.n_actions)
        self.values = None if values is None else np.asarray(values, np.float64)
        own = None if self.masked is None else np.asarray(measured, bool)
        self.noise = (float(noise) if noise is not None else float("nan") if values is None
                      else self._noise(obs, self.values, seed, own))

    def _standard(self, obs: np.ndarray) -> np.ndarray:
        return np.ascontiguousarray((np.asarray(obs, np.float64) - self.mean) / self.scale,
                                    dtype=np.float32)

    def rows(self, obs: np.ndarray, measured: np.ndarray | None = None) -> np.ndarray:
        """(S, m) the m nearest logged rows of each observation (S, d_o), nearest first;
        ``measured`` (S, d_o) bool its measured cells (None: all), read on a log with gaps."""
        obs = np.asarray(obs).reshape(len(obs), -1)
        out = np.empty((len(obs), self.nearest), np.int64)
        if self.masked is not None:
            qm = (np.ones(obs.shape, bool) if measured is None
                  else np.asarray(measured, bool).reshape(obs.shape))
            for a in range(0, len(obs), _BLOCK):
                out[a:a + _BLOCK] = self.masked.search(
                    self._standard(obs[a:a + _BLOCK]), qm[a:a + _BLOCK], self.nearest)[1]
            return out
        for a in range(0, len(obs), _BLOCK):
            _d, idx = self.index.search(self._standard(obs[a:a + _BLOCK]), self.nearest)
            out[a:a + _BLOCK] = idx
        return out

    def at(self, obs: np.ndarray, measured: np.ndarray | None = None) -> Near:
        """The neighbourhoods of observations (S, d_o), their measured cells ``measured``
        (S, d_o) bool or None (module docstring)."""
        rows = self.rows(obs, measured)
        acts = self.actions[rows]                                         # (S, m)
        s = len(rows)
        at = (np.repeat(np.arange(s), rows.shape[1]), acts.ravel())      # (query, action)
        rowcount = np.zeros((s, self.n_actions), np.int64)
        np.add.at(rowcount, at, 1)
        # distinct (action, episode) pairs per neighbourhood
        span = int(self.row_episode.max()) + 1
        key = np.sort(acts * span + self.row_episode[rows], axis=1)
        first = np.ones(key.shape, bool)
        first[:, 1:] = key[:, 1:] != key[:, :-1]
        episodes = np.zeros((s, self.n_actions), np.int64)
        q, j = np.nonzero(first)
        np.add.at(episodes, (q, key[q, j] // span), 1)
        mean = None
        if self.values is not None:
            total = np.zeros((s, self.n_actions))
            np.add.at(total, at, self.values[rows].ravel())
            with np.errstate(invalid="ignore", divide="ignore"):
                mean = np.where(rowcount > 0, total / rowcount, np.nan)
        return Near(episodes, rowcount.argmax(1).astype(np.int64), rows, mean)

    def _noise(self, obs: np.ndarray, values: np.ndarray, seed: int,
               measured: np.ndarray | None) -> float:
        """The pooled sd of a row's value about its (neighbourhood, action) mean (module
        docstring); NaN where no group has two rows."""
        n = len(obs)
        pick = np.sort(np.random.default_rng(seed).choice(n, size=min(NOISE_QUERIES, n),
                                                          replace=False))
        rows = self.rows(obs[pick], None if measured is None else measured[pick])  # (Q, m)
        acts, vals = self.actions[rows], values[rows]
        q = np.repeat(np.arange(len(rows)), rows.shape[1])
        group = q * self.n_actions + acts.ravel()
        count = np.bincount(group, minlength=len(rows) * self.n_actions)
        total = np.bincount(group, weights=vals.ravel(), minlength=len(count))
        mean = np.divide(total, count, out=np.zeros(len(count)), where=count > 0)
        dev = (vals.ravel() - mean[group]) ** 2
        dof = int(np.sum(np.maximum(count - 1, 0)))
        return float(np.sqrt(dev.sum() / dof)) if dof > 0 else float("nan")

    def lower(self, value: np.ndarray, episodes: np.ndarray) -> np.ndarray:
        """(S, K) v_hat - z_K noise / sqrt(episodes), -inf where no episode took the action;
        value and episodes (S, K) (the candidates are the discrete actions)."""
        with np.errstate(divide="ignore"):
            half = self.z * self.noise / np.sqrt(episodes.astype(np.float64))
        return np.where(episodes > 0, np.asarray(value, np.float64) - half, -np.inf)

    def bounds(self, near: Near) -> np.ndarray:
        """(S, n) each action's lower bound over the neighbourhood's own rows: the mean value
        of the rows that took it less z_K noise / sqrt(its episodes); -inf where none did."""
        return self.lower(np.nan_to_num(near.mean, nan=-np.inf), near.episodes)

    def describe(self) -> dict:
        """What the rule measured, for the record."""
        return {"nearest": self.nearest, "noise": self.noise, "z": self.z, "level": LEVEL,
                "queries": NOISE_QUERIES,
                "distance": "measured cells" if self.masked is not None else "l2"}


def measured_cells(corpus, rows: np.ndarray | None = None) -> np.ndarray | None:
    """(N, d_o) bool: the cells of a corpus (a store's ``Corpus`` or a ``CorpusData``) that
    were measured, not filled at ingest (of its ``rows`` (R,) where given: (R, d_o)); None
    where none was filled."""
    mask = getattr(corpus, "imputed_mask", None)
    if mask is None:
        mask = getattr(corpus, "imputed", None)
    if mask is None or not np.any(mask):
        return None
    mask = np.asarray(mask, bool)
    return ~(mask if rows is None else mask[np.asarray(rows)])


def episodes_near(observations: np.ndarray, actions: np.ndarray, episode_starts: np.ndarray,
                  n_actions: int, measured: np.ndarray | None = None) -> np.ndarray:
    """(N, n) the log's support near each of its own rows, in episodes: how many of its
    episodes among the :data:`NEAREST` rows nearest the row (itself among them) took each
    action (``aoc evaluate``'s hardly-held measure; rule 6's "held out fewer than 3 times in
    that state" where no state repeats). observations (N, d_o), actions (N,),
    episode_starts (E + 1,), measured (N, d_o) bool or None (the cells not filled)."""
    starts = np.asarray(episode_starts, np.int64)
    episode = np.repeat(np.arange(len(starts) - 1), np.diff(starts))
    hood = Neighbourhood(observations, actions, episode, n_actions, measured=measured)
    return hood.at(observations, measured).episodes


def neighbourhood_values(observations: np.ndarray, rewards: np.ndarray,
                         episode_starts: np.ndarray, gamma: float,
                         censored: np.ndarray | None = None, nearest: int = NEAREST,
                         tol: float = 1e-4, max_iterations: int = 1000, progress=None,
                         measured: np.ndarray | None = None, scale: np.ndarray | None = None
                         ) -> tuple[np.ndarray, dict]:
    """(values (N,), info): each row's value of the behaviour, by fitted Q evaluation over the
    log's neighbourhoods, the regressor the mean over the ``nearest`` rows (standardised,
    exact search; a k-nearest-neighbour FQE): y_i = r_i + gamma V(o_{i+1}), V(o) the mean y of
    the rows nearest o; y_i = r_i at an episode's last row, and at the cut of a ``censored``
    (E,) stay r_i + gamma V(o_i) (the stay goes on: its own neighbourhood stands for the next
    observation). Iterated from zero until no value moves by more than ``tol``
    times the rewards' range. observations (N, d_o), rewards (N,), episode_starts (E + 1,),
    measured (N, d_o) bool or None (the cells not filled: the masked distance).
    ``info``: nearest, iterations, converged, seconds, and ``rows`` (N, nearest) each row's
    neighbourhood (for :func:`fitted_values`). ``progress(done, total, text)`` follows the
    search."""
    started = time.perf_counter()
    obs = np.asarray(observations, np.float64).reshape(len(observations), -1)
    n = len(obs)
    r = np.asarray(rewards, np.float64).reshape(-1)
    starts = np.asarray(episode_starts, np.int64)
    hood = Neighbourhood(obs, np.zeros(n, np.int64), np.zeros(n, np.int64), 1, nearest=nearest,
                         measured=measured, scale=scale)
    own = None if hood.masked is None else np.asarray(measured, bool)
    rows = np.empty((n, hood.nearest), np.int64)
    for a in range(0, n, _BLOCK):
        rows[a:a + _BLOCK] = hood.rows(obs[a:a + _BLOCK],
                                       None if own is None else own[a:a + _BLOCK])
        if progress is not None:
            progress(min(a + _BLOCK, n), n, "the log's neighbourhoods")
    last = np.zeros(n, bool)
    last[starts[1:] - 1] = True
    nxt = np.minimum(np.arange(1, n + 1), n - 1)
    going = ~last                                   # rows whose next observation counts
    if censored is not None:
        cut = (starts[1:] - 1)[np.asarray(censored, bool)]
        nxt[cut] = cut
        going[cut] = True
    y = np.zeros(n)
    scale = max(float(np.ptp(r)), 1e-12) * tol
    done, it = False, 0
    for it in range(1, max_iterations + 1):
        new = r + np.where(going, gamma * y[rows].mean(1)[nxt], 0.0)
        moved = float(np.abs(new - y).max()) if n else 0.0
        y = new
        if moved <= scale:
            done = True
            break
    return y, {"nearest": hood.nearest, "iterations": it, "converged": done,
               "distance": hood.describe()["distance"],
               "seconds": round(time.perf_counter() - started, 3), "rows": rows}


def fitted_values(values: np.ndarray, actions: np.ndarray, rows: np.ndarray) -> np.ndarray:
    """(N,) the regressor's value at each row's own (observation, action): the mean of
    ``values`` (N,) over the rows of its neighbourhood ``rows`` (N, m) that took its action
    ``actions`` (N,) (the row itself among them, at distance 0). The one-step values
    :func:`neighbourhood_values` returns carry the noise of one next step (rule 7's bound
    needs it); these are what FQE fits, a smooth function of the observation and action that
    a belief can learn."""
    actions = np.asarray(actions).reshape(-1)
    same = actions[rows] == actions[:, None]                          # (N, m)
    same[:, 0] |= ~same.any(1)                   # a row missing from its own (ties): the nearest
    vals = np.asarray(values, np.float64)[rows]
    return (vals * same).sum(1) / same.sum(1)

