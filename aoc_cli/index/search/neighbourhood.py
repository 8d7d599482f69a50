"""The log's evidence near an observation, without exact repeats: rule 2 for continuous
observations and the clinicians' likely action that rule 7 keeps (docs/design.md, "Settings
from the log's evidence").

A cohort's rows are noisy measurements: no two rows repeat, so "the (state, action) the log
took n times" has no meaning. Its continuous form is the **neighbourhood** of an observation
o: every logged row within a radius of o's denoised position (:mod:`.denoise`: o replaced by
the mean of its 20 nearest logged rows, the rows' own denoised the same way; the radius 3
times the log's median squared distance to a 10th nearest row; 30 rows at least, 1,000 at
most; each column in its near-row spread), searched exactly (FAISS); on a log with filled
gaps (``measured``: the cells that are not the corpus's imputed ones) the denoising search
reads the cells both rows measured (:mod:`.masked`; a query's measured cells given with it,
else all of them). With ``nearest`` given, the neighbourhood is instead that many nearest raw
rows (each column in the log's sd): the rule before, kept for comparison. From the rows, for
every discrete action a:

* ``episodes[a]``: the distinct episodes among those rows that took a, the number of patients
  behind a's value at o (on a log whose states repeat, the rows at distance 0 are the state's
  own and inside the radius: the count is the exact-repeat support, up to 1,000 rows);
* ``likely``: the action most of those rows took, the clinicians' likely action at o (their
  modal action where states repeat);

and once for the log, ``noise``: the sd of a row's value about the mean value of the rows of
the same neighbourhood and action (pooled over a sample of :data:`NOISE_QUERIES` rows' own
neighbourhoods, each (neighbourhood, action) group with two rows or more), the spread of one
patient's value where the log cannot tell states apart.

The **values** the rule reads are the behaviour's Q by fitted Q evaluation over the
neighbourhoods (:func:`neighbourhood_values`, computed once by ``aoc train``): a row's value
is its reward plus gamma times the mean value of the rows near its next observation, to
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
near-row spread); ``at(obs (S, d_o), measured (S, d_o) or None)`` -> :class:`Near` with
episodes (S, n) int64, likely (S,) int64, rows :class:`~aoc_cli.index.search.denoise.Sets`
(S ragged sets).
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from statistics import NormalDist

import numpy as np

from aoc_cli.index.search.denoise import (CAP, LEAST, RADIUS, SAMPLE, Denoiser, RowSearch,
                                          Sets, near_row_spread)

#: Rows in an observation's neighbourhood, where its sets are of a fixed size.
NEAREST = 100
#: What the default sets are, as a model records them (``config.json`` ``neighbourhood``).
SETS = "denoised radius"
#: Rows whose neighbourhoods measure the noise (a seeded sample of the log).
NOISE_QUERIES = 2000
#: The bound's confidence, over the K actions of a step at once.
LEVEL = 0.95
#: Queries searched at once.
_BLOCK = 4096
#: The nearest rows read first for a set (more only where the last is inside the radius).
FIRST = 256


def lower_bound_z(n_actions: int, level: float = LEVEL) -> float:
    """z_K = Phi^-1(1 - (1 - level) / K) (Bonferroni over the K actions of a step)."""
    return float(NormalDist().inv_cdf(1.0 - (1.0 - level) / max(int(n_actions), 1)))


@dataclass(frozen=True)
class Near:
    """The neighbourhoods of S observations: ``episodes`` (S, n) distinct episodes per
    action, ``likely`` (S,) the action most rows took (ties: the lowest), ``rows`` the S
    sets of rows, nearest first, ``mean`` (S, n) their mean value per action."""

    episodes: np.ndarray
    likely: np.ndarray
    rows: Sets
    #: (S, n) the mean value of the rows that took each action (NaN: none; or no values)
    mean: np.ndarray | None = None


class Neighbourhood:
    """The logged rows near an observation (module docstring)."""

    def __init__(self, observations: np.ndarray, actions: np.ndarray, row_episode: np.ndarray,
                 n_actions: int, values: np.ndarray | None = None, nearest: int | None = None,
                 seed: int = 0, noise: float | None = None,
                 measured: np.ndarray | None = None, scale: np.ndarray | None = None,
                 space: dict | None = None):
        obs = np.asarray(observations, np.float64).reshape(len(observations), -1)
        self.actions = np.asarray(actions, np.int64)
        self.row_episode = np.asarray(row_episode, np.int64)
        self.n_actions = int(n_actions)
        own = None if measured is None or np.all(measured) else np.asarray(measured, bool)
        #: None: the denoised radius sets; a number: that many nearest raw rows
        self.nearest = None if nearest is None else int(min(nearest, len(obs)))
        self.denoiser = self.radius = None
        self._obs, self._own = obs, own
        if self.nearest is None and space is not None:    # as :meth:`space` gave it
            if np.shape(space["denoised"]) != obs.shape:
                raise ValueError(f"the neighbourhoods' denoised rows "
                                 f"{np.shape(space['denoised'])} are not of this log "
                                 f"{obs.shape}")
            self.denoiser = Denoiser(obs, own, space["scale"], seed=seed)
            self.search = RowSearch.of_standard(space["denoised"], space["centre"],
                                                space["scale"])
            self.denoised = np.asarray(space["denoised"], np.float32)
            self.radius = float(space["radius"])
        elif self.nearest is None:
            unit = near_row_spread(obs, own, seed=seed) if scale is None else scale
            self.denoiser = Denoiser(obs, own, unit, seed=seed)
            self.search = RowSearch(self.denoiser(obs, own), None, unit, seed=seed)
            #: (N, d) float32 the log's denoised rows, standardised (the index's own)
            self.denoised = self.search.index.reconstruct_n(0, len(obs))
            self.radius = self._radius(seed)
        else:
            unit = obs.std(0) if scale is None else np.asarray(scale, np.float64).reshape(-1)
            self.search = RowSearch(obs, own, unit, seed=seed)
        self.scale = self.search.scale
        #: the masked index over the raw rows where the log has filled cells, else None
        self.masked = (self.denoiser.search if self.denoiser is not None
                       else self.search).masked
        self.z = lower_bound_z(self.n_actions)
        self.values = None if values is None else np.asarray(values, np.float64)
        self.noise = (float(noise) if noise is not None else float("nan") if values is None
                      else self._noise(obs, self.values, seed, own))

    def space(self) -> dict | None:
        """What the denoised sets were built from, to build them again without denoising the
        log: ``scale`` and ``centre`` (d_o,), ``radius``, ``denoised`` (N, d_o) float32 the
        log's standardised denoised rows (None for fixed-size sets)."""
        if self.denoiser is None:
            return None
        return {"scale": self.search.scale, "centre": self.search.centre,
                "radius": self.radius, "denoised": self.denoised}

    def _radius(self, seed: int) -> float:
        """RADIUS times the median squared distance of a sample's denoised rows to their 10th
        nearest (the row itself first), in the near-row spread's units; above 0, so that an
        exact repeat's rows (distance 0) are inside."""
        n = self.search.n
        pick = np.sort(np.random.default_rng(seed).choice(n, size=min(SAMPLE, n),
                                                          replace=False))
        dist = self.search.index.search(self.denoised[pick], min(10, n))[0][:, -1]
        return max(RADIUS * float(np.median(dist)), 1e-9)

    def sets(self, obs: np.ndarray, measured: np.ndarray | None = None) -> Sets:
        """The logged rows near each observation (S, d_o), nearest first: every row within
        the radius of its denoised position (:mod:`.denoise`), else its ``nearest`` raw rows;
        ``measured`` (S, d_o) bool its measured cells (None: all), read on a log with gaps."""
        obs = np.asarray(obs, np.float64).reshape(len(obs), -1)
        if self.nearest is not None:
            return Sets.dense(self.rows(obs, measured))
        parts = []
        for a in range(0, len(obs), _BLOCK):
            part = None if measured is None else measured[a:a + _BLOCK]
            parts.append(self._within(self.search.standard(self.denoiser(obs[a:a + _BLOCK],
                                                                         part))))
        return Sets.join(parts)

    def log_sets(self, rows: np.ndarray | None = None) -> Sets:
        """The sets of the log's own rows (R,) (None: every row), from their denoised
        positions as the index holds them (no second denoising)."""
        rows = np.arange(len(self._obs)) if rows is None else np.asarray(rows, np.int64)
        if self.nearest is not None:
            return self.sets(self._obs[rows], None if self._own is None else self._own[rows])
        return Sets.join([self._within(self.denoised[rows[a:a + _BLOCK]])
                          for a in range(0, len(rows), _BLOCK)])

    def _within(self, q: np.ndarray) -> Sets:
        """The sets of standardised denoised queries q (S, d) float32: the rows within the
        radius, nearest first, at least LEAST and at most CAP (those the LEAST or CAP
        nearest). FAISS's k nearest, k = :data:`FIRST` and, for the queries whose k-th is
        still inside, CAP: a range search returns every row inside, thousands where the
        rows do not gather, to keep at most CAP."""
        n = self.search.n
        least, cap = min(LEAST, n), min(CAP, n)
        groups = [(np.arange(len(q)), *self.search.index.search(q, min(max(least, FIRST), cap)))]
        wide = groups[0][1][:, -1] < self.radius                # the k-th nearest inside
        if groups[0][1].shape[1] < cap and wide.any():
            groups.append((np.flatnonzero(wide), *self.search.index.search(q[wide], cap)))
            groups[0] = tuple(x[~wide] for x in groups[0])
        want = np.empty(len(q), np.int64)
        for at, d, _r in groups:
            want[at] = np.clip((d < self.radius).sum(1), least, cap)
        indptr = np.concatenate([[0], np.cumsum(want)])
        flat = np.empty(indptr[-1], np.int32)          # rows: below 2^31 in any log
        for at, _d, r in groups:
            keep = np.arange(r.shape[1]) < want[at][:, None]
            flat[(indptr[at][:, None] + np.arange(r.shape[1]))[keep]] = r[keep]
        return Sets(indptr, flat)

    def rows(self, obs: np.ndarray, measured: np.ndarray | None = None) -> np.ndarray:
        """(S, m) the ``nearest`` logged rows of each observation (S, d_o), nearest first
        (the fixed-size sets); ``measured`` (S, d_o) bool its measured cells (None: all)."""
        if self.nearest is None:
            raise ValueError("rows() reads fixed-size sets; use sets() for the radius sets")
        return self.search.search(obs, measured, self.nearest)[1]

    def at(self, obs: np.ndarray, measured: np.ndarray | None = None) -> Near:
        """The neighbourhoods of observations (S, d_o), their measured cells ``measured``
        (S, d_o) bool or None (module docstring)."""
        return self.near(self.sets(obs, measured))

    def near(self, sets: Sets) -> Near:
        """The neighbourhoods made of ``sets`` (S sets): episodes, likely action, mean (in
        blocks of sets, so that the (entries,) arrays stay small)."""
        s, k = len(sets), self.n_actions
        rowcount, episodes = np.zeros((s, k), np.int64), np.zeros((s, k), np.int64)
        mean = None if self.values is None else np.full((s, k), np.nan)
        span = int(self.row_episode.max()) + 1 if len(self.row_episode) else 1
        for a, b in sets.blocks():
            part = sets.part(a, b)
            group = part.owner() * k + self.actions[part.flat]        # (query, action)
            rowcount[a:b] = np.bincount(group, minlength=(b - a) * k).reshape(b - a, k)
            # distinct (query, action, episode) triples
            triple = np.unique(group * span + self.row_episode[part.flat])
            episodes[a:b] = np.bincount(triple // span,
                                        minlength=(b - a) * k).reshape(b - a, k)
            if mean is not None:
                total = np.bincount(group, weights=self.values[part.flat],
                                    minlength=(b - a) * k).reshape(b - a, k)
                have = rowcount[a:b] > 0
                mean[a:b][have] = total[have] / rowcount[a:b][have]
        return Near(episodes, rowcount.argmax(1).astype(np.int64), sets, mean)

    def _noise(self, obs: np.ndarray, values: np.ndarray, seed: int,
               measured: np.ndarray | None) -> float:
        """The pooled sd of a row's value about its (neighbourhood, action) mean (module
        docstring); NaN where no group has two rows."""
        n = len(obs)
        pick = np.sort(np.random.default_rng(seed).choice(n, size=min(NOISE_QUERIES, n),
                                                          replace=False))
        sets = self.log_sets(pick)
        vals = values[sets.flat]
        group = sets.owner() * self.n_actions + self.actions[sets.flat]
        count = np.bincount(group, minlength=len(sets) * self.n_actions)
        total = np.bincount(group, weights=vals, minlength=len(count))
        mean = np.divide(total, count, out=np.zeros(len(count)), where=count > 0)
        dev = (vals - mean[group]) ** 2
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
        out = {"nearest": self.nearest, "noise": self.noise, "z": self.z, "level": LEVEL,
               "queries": NOISE_QUERIES,
               "distance": "measured cells" if self.masked is not None else "l2"}
        if self.denoiser is not None:
            out.update(sets=SETS, smooth=self.denoiser.smooth,
                       radius_multiple=RADIUS, radius=self.radius, least=LEAST, cap=CAP)
        return out


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
    episodes among the rows of the row's neighbourhood (itself among them) took each
    action (``aoc evaluate``'s hardly-held measure; rule 6's "held out fewer than 3 times in
    that state" where no state repeats). observations (N, d_o), actions (N,),
    episode_starts (E + 1,), measured (N, d_o) bool or None (the cells not filled)."""
    starts = np.asarray(episode_starts, np.int64)
    episode = np.repeat(np.arange(len(starts) - 1), np.diff(starts))
    hood = Neighbourhood(observations, actions, episode, n_actions, measured=measured)
    return hood.near(hood.log_sets()).episodes


def neighbourhood_values(observations: np.ndarray, rewards: np.ndarray,
                         episode_starts: np.ndarray, gamma: float,
                         censored: np.ndarray | None = None, nearest: int | None = None,
                         tol: float = 1e-4, max_iterations: int = 1000, progress=None,
                         measured: np.ndarray | None = None, scale: np.ndarray | None = None
                         ) -> tuple[np.ndarray, dict]:
    """(values (N,), info): each row's value of the behaviour, by fitted Q evaluation over the
    log's neighbourhoods, the regressor the mean over a row's set (:class:`Neighbourhood`'s
    sets: the denoised radius sets, or the ``nearest`` raw rows; a nearest-neighbour FQE):
    y_i = r_i + gamma V(o_{i+1}), V(o) the mean y of the rows of o's set; y_i = r_i at an
    episode's last row, and at the cut of a ``censored`` (E,) stay r_i + gamma V(o_i) (the
    stay goes on: its own set stands for the next observation). Iterated from zero until no
    value moves by more than ``tol`` times the rewards' range. observations (N, d_o), rewards
    (N,), episode_starts (E + 1,), measured (N, d_o) bool or None (the cells not filled: the
    masked distance). ``info``: nearest, iterations, converged, seconds, the sets' sizes,
    ``rows`` (:class:`~aoc_cli.index.search.denoise.Sets`, N sets) each row's set (for
    :func:`fitted_values`) and ``space`` (:meth:`Neighbourhood.space`, saved with a model).
    ``progress(done, total, text)`` follows the search."""
    started = time.perf_counter()
    obs = np.asarray(observations, np.float64).reshape(len(observations), -1)
    n = len(obs)
    r = np.asarray(rewards, np.float64).reshape(-1)
    starts = np.asarray(episode_starts, np.int64)
    hood = Neighbourhood(obs, np.zeros(n, np.int64), np.zeros(n, np.int64), 1, nearest=nearest,
                         measured=measured, scale=scale)
    parts = []
    for a in range(0, n, _BLOCK):
        parts.append(hood.log_sets(np.arange(a, min(a + _BLOCK, n))))
        if progress is not None:
            progress(min(a + _BLOCK, n), n, "the log's neighbourhoods")
    sets = Sets.join(parts)
    del parts
    average = sets.averaging(n)                     # (N, N) sparse: the mean over a set
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
        new = r + np.where(going, gamma * (average @ y)[nxt], 0.0)
        moved = float(np.abs(new - y).max()) if n else 0.0
        y = new
        if moved <= scale:
            done = True
            break
    size = sets.sizes
    made = {k: v for k, v in hood.describe().items() if k not in ("noise", "z", "level",
                                                                   "queries")}
    made["set_rows"] = {"median": float(np.median(size)) if n else 0.0,
                        "least": int(size.min()) if n else 0,
                        "most": int(size.max()) if n else 0}
    space = hood.space()
    made["space"] = None if space is None else {**space, "set_rows": made["set_rows"]}
    return y, {**made, "iterations": it, "converged": done,
               "seconds": round(time.perf_counter() - started, 3), "rows": sets}


def fitted_values(values: np.ndarray, actions: np.ndarray, rows: Sets) -> np.ndarray:
    """(N,) the regressor's value at each row's own (observation, action): the mean of
    ``values`` (N,) over the rows of its set ``rows`` (N sets) that took its action
    ``actions`` (N,) (the row itself among them, at distance 0). The one-step values
    :func:`neighbourhood_values` returns carry the noise of one next step (rule 7's bound
    needs it); these are what FQE fits, a smooth function of the observation and action that
    a belief can learn."""
    actions = np.asarray(actions).reshape(-1)
    values = np.asarray(values, np.float64)
    if not isinstance(rows, Sets):
        rows = Sets.dense(rows)
    out = np.empty(len(rows))
    for a, b in rows.blocks():                      # blocks: (nnz,) arrays stay small
        part = rows.part(a, b)
        owner = part.owner()
        same = (actions[part.flat] == actions[a + owner]).astype(np.float64)
        alone = np.bincount(owner, weights=same, minlength=b - a) == 0
        # a row missing from its own set (ties) reads its nearest row's value
        same[part.indptr[:-1][alone]] = 1.0
        total = np.bincount(owner, weights=values[part.flat] * same, minlength=b - a)
        out[a:b] = total / np.bincount(owner, weights=same, minlength=b - a)
    return out
