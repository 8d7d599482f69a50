"""icu-cohort: a clinical cohort table drawn from the ICU-Sepsis MDP, with a known truth.

A test bed for the cohort path (``aoc ingest`` of a table with gaps, outcomes and censored
stays): the patients of :mod:`aoc_cli.envs.icu_sepsis` (its 716-state MDP, the clinicians'
policy), but a row shows the 47 AI-Clinician features of the state's cluster centre plus
Gaussian noise (sd ``noise``, the package's units), ``gap`` of the cells empty. The
environment replays the MDP through the same noise: ``aoc rollout --env icu-cohort`` measures
a policy's true survival, :func:`rollout_value` for thousands of episodes at once.

The table (:func:`cohort_table`, written by ``scripts/icu_cohort.py``), one row per stay per
4-hour step, in stay order, columns named so that ``aoc ingest`` finds their roles by itself:

* ``id`` the stay, ``time`` its step (1-based, the AI Clinician's ``bloc``);
* ``obs_<FEATURE>`` for the 47 :data:`~aoc_cli.envs.icu_sepsis.FEATURES`: the true state's
  centre + N(0, noise^2) per cell, float32; empty (NaN) at rate ``gap``, never on a stay's
  first step (``--impute hold`` never falls back to a median);
* ``act_dose`` the clinicians' dose level, ``5 * fluids + vaso`` (0-24, as icu-sepsis's
  actions), sampled from their policy in the true state;
* ``died_in_hosp`` 0/1 on every row of the stay; empty for a stay cut short: a ``censored``
  share of the stays is cut at a uniformly random step before its end (and a stay still under
  treatment after 500 steps has no outcome either).

Not written: ``state`` and ``propensity`` (of the logged dose), the truth (:data:`HIDDEN`).
Ingested with ``aoc ingest cohort.csv --name c --discrete-actions --impute hold --outcome
died_in_hosp --outcome-reward 1=0,0=1`` its reward is 1 on a surviving stay's last step.
``aoc collect icu-cohort`` logs the same arrays (and ``state``, ``propensity``, the gaps as
the imputed mask) for the same seed.

The environment (``make_env("icu-cohort")``, ``make_env("icu-cohort:noise=1.0,gap=0.15")``):
the 47 features of the current state with fresh noise every step, a cell missing at rate
``gap`` held from the episode's last value (the first step fully measured); 25 actions; reward
1 on the step into survival; terminal at death or survival, truncated after 500 steps;
``info["state"]`` the true state, ``info["measured"]`` (47,) bool the cells measured (false:
held); ``reset(seed=)`` reproduces an episode. References:
:func:`clinicians_value` (exact), :func:`nearest_centre_policy` (a state policy in the state
whose centre is nearest the observation), :func:`optimal_state_policy`.
"""

from __future__ import annotations

from typing import Callable

import gymnasium
import numpy as np

from aoc_cli.envs import icu_sepsis as sepsis
from aoc_cli.envs.base import Progress, Task, budget
from aoc_cli.envs.render import step_series
from aoc_cli.errors import AocError
from aoc_cli.store import CorpusData, box_space, discrete_space, episode_starts_from_lengths

GYM_ID = "aoc/ICUCohort-v0"
NAME = "icu-cohort"
NOISE, GAP, CENSORED = 0.3, 0.15, 0.03
#: The settings ``make_env("icu-cohort:noise=1.0,gap=0.15")`` takes, with their defaults.
SETTINGS = {"noise": NOISE, "gap": GAP}
N_FEATURES = len(sepsis.FEATURES)
ID, TIME, ACTION, OUTCOME = "id", "time", "act_dose", "died_in_hosp"
OBS_COLUMNS = tuple(f"obs_{f}" for f in sepsis.FEATURES)
#: Keys of :func:`cohort_table` that are not columns of the table (the truth, for tests).
HIDDEN = ("state", "propensity")
MAX_STEPS = sepsis.MAX_STEPS
DEFAULT_EPISODES = 10_000
POLICIES = ("clinicians",)
#: First stay id (ids are FIRST_ID, FIRST_ID + 1, ...).
FIRST_ID = 200_000

DecideBatch = Callable[[np.ndarray], np.ndarray]


def centres(strategy: str = "mean") -> np.ndarray:
    """(716, 47) float64 the cluster centre of each state (the terminal states' too)."""
    return sepsis.tables(strategy).observations[:, :N_FEATURES]


def _check(noise: float, gap: float, censored: float = 0.0) -> None:
    """noise a finite number >= 0; gap in [0, 1); censored in [0, 1]."""
    for key, value, ok in (("noise", noise, lambda v: 0.0 <= v < np.inf),
                           ("gap", gap, lambda v: 0.0 <= v < 1.0),
                           ("censored", censored, lambda v: 0.0 <= v <= 1.0)):
        if isinstance(value, bool) or not isinstance(value, (int, float, np.floating)) or \
                not ok(float(value)):
            raise AocError(f"icu-cohort: {key} must be "
                           + {"noise": "a finite number >= 0", "gap": "in [0, 1)",
                              "censored": "in [0, 1]"}[key] + f", got {value!r}")


def _noisy(centre: np.ndarray, noise: float, rng: np.random.Generator) -> np.ndarray:
    """(n, 47) float32: centres plus N(0, noise^2) per cell."""
    return np.asarray(centre + rng.normal(0.0, 1.0, centre.shape) * noise if noise else centre,
                      dtype=np.float32)


def hold_forward(values: np.ndarray, starts: np.ndarray) -> np.ndarray:
    """(N, d) with each NaN cell the last non-NaN value of its column within its episode
    (``starts`` (E + 1,) offsets); the first row of every episode must be fully measured."""
    n = len(values)
    if n == 0:
        return values.copy()
    measured = ~np.isnan(values)
    if not measured[starts[:-1]].all():
        raise AocError("internal: a stay's first step has an empty cell")
    idx = np.where(measured, np.arange(n)[:, None], 0)
    np.maximum.accumulate(idx, axis=0, out=idx)  # never crosses a stay: its first row is set
    return np.take_along_axis(values, idx, axis=0)


# -- the table ----------------------------------------------------------------------------------

def cohort_table(stays: int, noise: float = NOISE, gap: float = GAP,
                 censored: float = CENSORED, seed: int = 0, strategy: str = "mean",
                 progress: Progress | None = None) -> dict[str, np.ndarray]:
    """The cohort's columns in stay order: ``id``, ``time`` (1-based), the 47 ``obs_*``
    features (float32, NaN where empty), ``act_dose`` (int64 0-24), ``died_in_hosp`` (0/1, NaN
    for a censored stay), and the hidden truth ``state`` and ``propensity`` (:data:`HIDDEN`).
    Same arguments, same arrays."""
    _check(noise, gap, censored)
    if int(stays) != stays or stays < 1:
        raise AocError(f"icu-cohort: stays must be a positive integer, got {stays}")
    t = sepsis.tables(strategy)
    rng = np.random.default_rng(seed)
    sim = sepsis.simulate(t, t.clinicians, int(stays), rng, progress)
    lengths = sim["lengths"].copy()
    ends = np.cumsum(lengths)
    survived = sim["terminal"] & (sim["reward"][ends - 1] == 1.0)
    known = sim["terminal"].copy()
    # censoring: a share of the stays cut at a uniformly random step before their end
    cut = rng.random(len(lengths)) < censored
    keep_len = np.where(cut & (lengths > 1),
                        np.floor(rng.random(len(lengths)) * (lengths - 1)).astype(np.int64) + 1,
                        lengths)
    known &= ~cut
    old_starts = episode_starts_from_lengths(lengths)
    stay_of_row = np.repeat(np.arange(len(lengths)), lengths)
    step = np.arange(len(stay_of_row)) - old_starts[stay_of_row]
    rows = step < keep_len[stay_of_row]
    stay_of_row, step = stay_of_row[rows], step[rows]
    state = sim["state"][rows]
    n = len(state)
    feats = _noisy(centres(strategy)[state], noise, rng)
    empty = rng.random((n, N_FEATURES)) < gap
    empty[step == 0] = False
    feats[empty] = np.nan
    died = np.where(known, (~survived).astype(np.float64), np.nan)
    cols: dict[str, np.ndarray] = {ID: FIRST_ID + stay_of_row.astype(np.int64),
                                   TIME: step.astype(np.int64) + 1}
    for j, name in enumerate(OBS_COLUMNS):
        cols[name] = feats[:, j]
    cols[ACTION] = sim["action"][rows].astype(np.int64)
    cols[OUTCOME] = died[stay_of_row]
    cols["state"] = state.astype(np.int64)
    cols["propensity"] = sim["propensity"][rows]
    return cols


def table_corpus(cols: dict[str, np.ndarray], source: dict | None = None) -> CorpusData:
    """The corpus of a :func:`cohort_table` as ``aoc ingest --impute hold --outcome
    died_in_hosp --outcome-reward 1=0,0=1 --discrete-actions`` reads it: observations the
    features held forward within the stay, reward 1 on the last step of a stay that survived,
    a stay without outcome truncated, the empty cells the imputed mask; columns ``state``,
    ``propensity``; tag ``policy``."""
    ids = cols[ID]
    n = len(ids)
    new = np.ones(n, dtype=bool)
    new[1:] = ids[1:] != ids[:-1]
    starts = np.append(np.flatnonzero(new), n).astype(np.int64)
    last = starts[1:] - 1
    raw = np.stack([cols[c] for c in OBS_COLUMNS], axis=1)
    empty = np.isnan(raw)
    obs = hold_forward(raw, starts)
    outcome = cols[OUTCOME][last]
    known = ~np.isnan(outcome)
    rewards = np.zeros(n)
    rewards[last[known]] = 1.0 - outcome[known]
    terminals = np.zeros(n, dtype=bool)
    truncations = np.zeros(n, dtype=bool)
    terminals[last[known]] = True
    truncations[last[~known]] = True
    return CorpusData(
        observations=obs.astype(np.float32), actions=cols[ACTION].astype(np.int64),
        rewards=rewards, terminals=terminals, truncations=truncations, episode_starts=starts,
        imputed=empty if empty.any() else None,
        observation_space=box_space(N_FEATURES, names=list(OBS_COLUMNS)),
        action_space=discrete_space(len(sepsis.ACTION_NAMES), names=list(sepsis.ACTION_NAMES)),
        tags={"policy": (np.zeros(n, dtype=np.int32), list(POLICIES))},
        columns={"state": cols["state"].astype(np.float64),
                 "propensity": cols["propensity"].astype(np.float64)},
        episode_ids=[str(i) for i in ids[starts[:-1]]],
        source=source or {},
    ).validate()


# -- aoc collect icu-cohort ---------------------------------------------------------------------

def collect_data(steps: int | None = None, episodes: int | None = None, seed: int = 0,
                 progress: Progress | None = None, policy: str = "clinicians",
                 noise: float = NOISE, gap: float = GAP, censored: float = CENSORED,
                 strategy: str = "mean") -> tuple[CorpusData, list[dict]]:
    """The clinicians' log of ``episodes`` stays (or the first ``steps`` rows of as many as
    hold them), as the CSV of :func:`cohort_table` with the same seed reads once ingested."""
    if policy not in POLICIES:
        raise AocError(f"unknown policy {policy!r} for {NAME}: use {' or '.join(POLICIES)}")
    steps, episodes = budget(steps, episodes, None, DEFAULT_EPISODES)
    stays = episodes if episodes is not None else max(64, steps // 8 + 1)
    while True:
        cols = cohort_table(stays, noise, gap, censored, seed, strategy,
                            progress if episodes is not None else None)
        if steps is None or len(cols[ID]) >= steps:
            break
        stays *= 2
    data = table_corpus(cols)
    if steps is not None:
        data = _first_rows(data, steps)
    data.source = {"kind": "collect", "task": NAME, "seed": int(seed), "steps": steps,
                   "episodes": episodes, "policy": policy, "strategy": strategy,
                   "noise": float(noise), "gap": float(gap), "censored": float(censored)}
    t = sepsis.tables(strategy)
    return data, sepsis.summary(data, t, t.clinicians, policy)


def _first_rows(data: CorpusData, steps: int) -> CorpusData:
    """The first ``steps`` rows (the last stay kept cut short: truncated)."""
    starts = data.episode_starts
    keep = int(np.searchsorted(starts, steps, side="left"))  # stays starting before `steps`
    new_starts = np.append(starts[:keep], steps).astype(np.int64)
    terminals = data.terminals[:steps].copy()
    truncations = data.truncations[:steps].copy()
    rewards = data.rewards[:steps].copy()
    if not (terminals[-1] or truncations[-1]):
        truncations[-1] = True
    return CorpusData(
        observations=data.observations[:steps], actions=data.actions[:steps], rewards=rewards,
        terminals=terminals, truncations=truncations, episode_starts=new_starts,
        imputed=None if data.imputed is None else data.imputed[:steps],
        observation_space=data.observation_space, action_space=data.action_space,
        tags={k: (v[0][:steps], v[1]) for k, v in data.tags.items()},
        columns={k: v[:steps] for k, v in data.columns.items()},
        episode_ids=list(data.episode_ids[:keep]),
    ).validate()


# -- the environment ----------------------------------------------------------------------------

class CohortEnv(gymnasium.Env):
    """The ICU-Sepsis MDP observed through the cohort's noisy features (module docstring)."""

    metadata = {"render_modes": []}

    def __init__(self, noise: float = NOISE, gap: float = GAP, strategy: str = "mean",
                 render_mode=None):
        _check(noise, gap)
        self.noise, self.gap = float(noise), float(gap)
        t = sepsis.tables(strategy)
        self._P, self._d0, self._terminal = t.mdp.P, t.mdp.d0, t.mdp.terminal
        self._centres = centres(strategy)
        self.observation_space = gymnasium.spaces.Box(-np.inf, np.inf, (N_FEATURES,),
                                                      np.float32)
        self.action_space = gymnasium.spaces.Discrete(len(sepsis.ACTION_NAMES))
        self.render_mode = render_mode
        self._state: int | None = None
        self._obs: np.ndarray | None = None

    def _observe(self, first: bool) -> tuple[np.ndarray, dict]:   # (observation, info)
        fresh = _noisy(self._centres[self._state][None], self.noise, self.np_random)[0]
        held = np.zeros(N_FEATURES, bool)
        if not first and self.gap:
            held = self.np_random.random(N_FEATURES) < self.gap
            fresh[held] = self._obs[held]
        self._obs = fresh
        return fresh.copy(), {"state": self._state, "measured": ~held}

    def reset(self, *, seed=None, options=None):
        super().reset(seed=seed)
        self._state = int(self.np_random.choice(len(self._d0), p=self._d0))
        return self._observe(True)

    def step(self, action):
        if self._state is None or self._terminal[self._state]:
            raise AocError("icu-cohort: step() after the episode ended: call reset()")
        a = int(action)
        if not 0 <= a < self.action_space.n:
            raise AocError(f"icu-cohort: action {action} outside 0..{self.action_space.n - 1}")
        self._state = int(self.np_random.choice(len(self._d0), p=self._P[self._state, a]))
        obs, info = self._observe(False)
        return obs, float(self._state == sepsis.STATE_SURVIVAL), \
            bool(self._terminal[self._state]), False, info


# -- true survival by Monte Carlo, and the references -------------------------------------------

def rollout_value(decide_batch: DecideBatch, n_episodes: int, noise: float = NOISE,
                  gap: float = GAP, seed: int = 0, strategy: str = "mean") -> dict:
    """Survival of a policy deciding from the observations alone, ``n_episodes`` episodes run
    at once in the MDP through the environment's noise, gaps and hold: ``decide_batch(obs (n,
    47) float32) -> actions (n,) int`` once a step on the episodes alive (one with a
    ``reset(n)`` method, e.g. :class:`aoc_cli.control.batch.BatchPolicy`, is reset first and
    called as ``decide_batch(obs, alive, measured)``: ``alive`` their indices, ``measured``
    (n, 47) bool the cells not held). Returns ``{"value", "low", "high", "episodes",
    "survived"}``: the 95% normal interval, ``survived`` (n,) bool (alive after 500 steps: not
    survived). The draws are **common random numbers**: episode i's first state, noise, gaps
    and next-state uniforms at step t come from a stream of (seed, t) alone, so two policies
    rolled out with one seed meet the same patients and, where they choose alike, the same
    courses (:func:`paired_difference`)."""
    _check(noise, gap)
    t, C, n = sepsis.tables(strategy), centres(strategy), int(n_episodes)
    rng = np.random.default_rng([int(seed), 0])
    s = sepsis._sample(np.broadcast_to(np.cumsum(t.mdp.d0)[None], (n, len(t.mdp.d0))),
                       rng.random(n))
    obs, alive, survived = _noisy(C[s], noise, rng), np.arange(n), np.zeros(n, dtype=bool)
    measured = np.ones(obs.shape, bool)
    stateful = hasattr(decide_batch, "reset")
    if stateful:
        decide_batch.reset(n)
    for step in range(1, MAX_STEPS + 1):
        if len(alive) == 0:
            break
        a = np.asarray(decide_batch(obs, alive, measured) if stateful else decide_batch(obs),
                       dtype=np.int64).reshape(-1)
        if len(a) != len(alive) or a.min() < 0 or a.max() >= t.mdp.P.shape[1]:
            raise AocError(f"decide_batch gave {len(a)} actions in "
                           f"{a.min() if len(a) else '-'}..{a.max() if len(a) else '-'} for "
                           f"{len(alive)} observations: expected one in 0..24 each")
        rng = np.random.default_rng([int(seed), step])    # every episode's draws of the step
        pick, fresh = rng.random(n)[alive], rng.normal(0.0, 1.0, (n, N_FEATURES))[alive]
        held = (rng.random((n, N_FEATURES)) < gap)[alive]
        nxt = sepsis._sample(np.cumsum(t.mdp.P[s, a], axis=1), pick)
        ended = t.mdp.terminal[nxt]
        survived[alive[nxt == sepsis.STATE_SURVIVAL]] = True
        new = (C[nxt] + fresh * noise if noise else C[nxt].copy()).astype(np.float32)
        if gap:
            new[held] = obs[held]
        alive, s, obs, measured = alive[~ended], nxt[~ended], new[~ended], ~held[~ended]
    value = float(survived.mean())
    half = 1.96 * np.sqrt(value * (1 - value) / n)
    return {"value": value, "low": value - half, "high": value + half, "episodes": n,
            "survived": survived}


def paired_difference(a: np.ndarray, b: np.ndarray) -> dict:
    """The mean difference in survival of two policies rolled out on the same episodes
    (``survived`` (n,) each, one seed), with its 95% normal interval from the per-episode
    differences: ``{"difference", "low", "high", "differ"}`` (the share that differ)."""
    d = np.asarray(a, np.float64) - np.asarray(b, np.float64)
    if d.ndim != 1 or len(d) < 2:
        raise AocError("paired_difference: two (n,) outcome arrays of the same episodes")
    half, m = 1.96 * float(d.std(ddof=1)) / np.sqrt(len(d)), float(d.mean())
    return {"difference": m, "low": m - half, "high": m + half, "differ": float(np.mean(d != 0))}


def nearest_state(obs: np.ndarray, strategy: str = "mean") -> np.ndarray:
    """(n,) int64 the non-terminal state whose centre is nearest each observation (n, 47)."""
    C = centres(strategy)[:sepsis.STATE_DEATH]
    d = (C * C).sum(1)[None, :] - 2.0 * np.asarray(obs, dtype=np.float64) @ C.T
    return np.argmin(d, axis=1).astype(np.int64)


def nearest_centre_policy(state_policy: np.ndarray, seed: int = 0,
                          strategy: str = "mean") -> DecideBatch:
    """A ``decide_batch`` acting as ``state_policy`` in the state whose cluster centre is
    nearest the observation: (716,) int actions, or (716, 25) probabilities (sampled, from
    ``seed``)."""
    pi = np.asarray(state_policy)
    rng = np.random.default_rng(seed)
    if pi.ndim == 1:
        return lambda obs: pi[nearest_state(obs, strategy)].astype(np.int64)
    cum = np.cumsum(pi, axis=1)
    return lambda obs: sepsis._sample(cum[nearest_state(obs, strategy)], rng.random(len(obs)))


def clinicians_value(strategy: str = "mean") -> float:
    """The clinicians' exact survival."""
    return sepsis.tables(strategy).mdp.value(sepsis.tables(strategy).clinicians)


def optimal_state_policy(strategy: str = "mean") -> np.ndarray:
    """(716,) int64 an optimal policy of the MDP (it sees the state)."""
    return sepsis.tables(strategy).mdp.optimal()[1]


# -- the task -----------------------------------------------------------------------------------

def _make(noise: float = NOISE, gap: float = GAP, **kw) -> gymnasium.Env:
    return gymnasium.make(GYM_ID, noise=float(noise), gap=float(gap), **kw)


_plot, _trajectory = step_series(NAME, "SOFA (noisy)", sepsis.FEATURES.index("SOFA"))

TASKS = [
    Task(name=NAME, gym_id=GYM_ID,
         description="ICU-Sepsis through a cohort table's noisy features (sd 0.3), 15% gaps "
                     "held forward: the true survival of a cohort-trained policy",
         horizon=MAX_STEPS, policies=POLICIES, make_fn=_make,
         collect_fn=lambda steps=None, episodes=None, seed=0, progress=None,
         policy="clinicians", **kw: collect_data(steps, episodes, seed, progress, policy, **kw),
         plot_fn=_plot, trajectory_fn=_trajectory, default_episodes=DEFAULT_EPISODES,
         extra={"strategy": "mean", "settings": dict(SETTINGS),
                "units": "the package's normalised values (each state's cluster centre: binary "
                         "features minus 0.5, the others z-scored, some after a log) plus "
                         "Gaussian noise"}),
]
