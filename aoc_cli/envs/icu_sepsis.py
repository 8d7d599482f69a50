"""icu-sepsis: sepsis treatment in intensive care, an MDP estimated from real MIMIC-III patients.

The tables come from the ``icu-sepsis`` package (Choudhary, Gupta, Thomas, RLC 2024; MIT), read
from its wheel with its own loader (``icu_sepsis.utils.io.MDPParameters``); nothing is fetched:

* 716 states: 713 of a patient under treatment, then death (713), survival (714) and ``s_inf``
  (715), all three terminal; 25 actions, 5 IV-fluid x 5 vasopressor dose levels, action
  ``5 * fluids + vaso``, labelled ``fluids=2,vaso=0``;
* reward +1 on the step into survival, 0 otherwise (undiscounted: the return is survival);
* the initial distribution, the clinicians' estimated policy ``expert_policy`` (716, 25), and per
  state a 47-feature physiological vector (the state's cluster centre, normalised as the
  package's MDP build normalises MIMIC: binary columns - 0.5, the others z-scored, some after a
  log) and its mean SOFA score;
* an action outside the clinicians' admissible set of a state (actions they took there at
  least 20 times) moves as the mean of the admissible actions (strategy ``'mean'``, the default
  and the paper's) or, in the ``terminate`` variant, sends the patient to death.

Observations are the 47 features named as in the package's build (:data:`FEATURES`), then
``sofa_score`` (as ``info["sofa_score"]`` of the package's environment): 48 numbers. The corpus
of ``aoc collect icu-sepsis`` also holds, per row, the discrete state (column ``state``) and the
behaviour's probability of the logged action in it (column ``propensity``), the behaviour as tag
``policy`` and one patient id per episode. Episodes end at a terminal state or, as the package's
environment does, after 500 steps (truncated).

Exact values of state-based policies: :func:`tables` and :class:`aoc_cli.envs.tabular.TabularMDP`
(``tables().mdp.value(policy)``).

The package imports the old ``gym``, which prints a deprecation banner on import: every import
of it here goes through :func:`package`, which keeps the banner (and its warnings) out of aoc's
output. The package is imported on first use only, so ``import aoc_cli.envs`` stays fast.
"""

from __future__ import annotations

import contextlib
import io
import warnings
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path

import gymnasium
import numpy as np

from aoc_cli.envs.base import Progress, Task, budget
from aoc_cli.envs.render import step_series
from aoc_cli.envs.tabular import TabularMDP
from aoc_cli.errors import AocError
from aoc_cli.store import CorpusData, box_space, discrete_space, episode_starts_from_lengths

GYM_ID = "aoc/ICUSepsis-v0"
GYM_ID_TERMINATE = "aoc/ICUSepsisTerminate-v0"
#: task name -> the package's inadmissible-action strategy.
STRATEGIES = {"icu-sepsis": "mean", "icu-sepsis-terminate": "terminate"}
#: The 47 state features in the order of the package's cluster centres: its MDP build
#: (``icu_sepsis_helpers.mdp_creation.create_rl_table``: binary, then normal, then log columns).
FEATURES = (
    "gender", "mechvent", "max_dose_vaso", "re_admission",
    "age", "Weight_kg", "GCS", "HR", "SysBP", "MeanBP", "DiaBP", "RR", "Temp_C", "FiO2_1",
    "Potassium", "Sodium", "Chloride", "Glucose", "Magnesium", "Calcium", "Hb", "WBC_count",
    "Platelets_count", "PTT", "PT", "Arterial_pH", "paO2", "paCO2", "Arterial_BE", "HCO3",
    "Arterial_lactate", "SOFA", "SIRS", "Shock_Index", "PaO2_FiO2", "cumulated_balance",
    "SpO2", "BUN", "Creatinine", "SGOT", "SGPT", "Total_bili", "INR", "input_total",
    "input_4hourly", "output_total", "output_4hourly",
)
OBS_NAMES = FEATURES + ("sofa_score",)
LEVELS = 5
ACTION_NAMES = tuple(f"fluids={f},vaso={v}" for f in range(LEVELS) for v in range(LEVELS))
STATE_DEATH, STATE_SURVIVAL, STATE_S_INF = 713, 714, 715
MAX_STEPS = 500
DEFAULT_EPISODES = 10_000
POLICIES = ("clinicians", "random")
#: Episodes simulated at once (bounds the (n, 716) transition rows gathered per step).
BATCH = 4096


def package():
    """The ``icu_sepsis`` module, imported with the old gym's banner and warnings kept out of
    stdout and stderr."""
    sink = io.StringIO()
    with warnings.catch_warnings(), contextlib.redirect_stderr(sink), \
            contextlib.redirect_stdout(sink):
        warnings.simplefilter("ignore")
        try:
            import icu_sepsis
            from icu_sepsis.envs import sepsis  # noqa: F401
        except ImportError as err:  # pragma: no cover - a real dependency
            raise AocError(f"the icu-sepsis task needs the icu-sepsis package ({err}): "
                           "`pip install icu-sepsis==2.0.1` (make install does)") from err
    return icu_sepsis


@lru_cache(maxsize=1)
def parameters():
    """The package's MDP parameters, read from its wheel by its own loader (cached)."""
    pkg = package()
    from icu_sepsis.envs import sepsis
    from icu_sepsis.utils.io import MDPParameters

    del pkg
    return MDPParameters(Path(sepsis.__file__).parent / "assets")


@dataclass(frozen=True)
class SepsisTables:
    """The package's tables under one strategy: ``mdp`` (transitions (716, 25, 716) with the
    strategy applied, expected rewards (716, 25), initial distribution, terminal states);
    ``clinicians`` (716, 25) the estimated expert policy; ``admissible`` (716, 25) bool;
    ``observations`` (716, 48) the 47 features and the SOFA score of each state."""

    strategy: str
    mdp: TabularMDP
    clinicians: np.ndarray
    admissible: np.ndarray
    observations: np.ndarray

    def behaviour(self, name: str) -> np.ndarray:
        """(716, 25) a behaviour policy: ``clinicians`` or ``random`` (uniform)."""
        if name == "clinicians":
            return self.clinicians
        if name == "random":
            pi = np.full(self.clinicians.shape, 1.0 / self.clinicians.shape[1])
            pi[self.mdp.terminal] = 0.0
            return pi
        raise AocError(f"unknown policy {name!r}: use {' or '.join(POLICIES)}")

    def modal(self) -> np.ndarray:
        """(716,) int64 the clinicians' most frequent action per state (ties: lowest index)."""
        return np.argmax(self.clinicians, axis=1).astype(np.int64)


@lru_cache(maxsize=2)
def tables(strategy: str = "mean") -> SepsisTables:
    """The tables under the inadmissible-action ``strategy`` (``mean`` or ``terminate``)."""
    if strategy not in ("mean", "terminate"):
        raise AocError(f"unknown inadmissible-action strategy {strategy!r}: use mean or "
                       "terminate")
    p = parameters()
    P = np.asarray(p.tx_mat, dtype=np.float64)
    R = np.asarray(p.r_mat, dtype=np.float64)
    S, A = P.shape[:2]
    terminal = np.zeros(S, dtype=bool)
    terminal[[STATE_DEATH, STATE_SURVIVAL, STATE_S_INF]] = True
    admissible = np.zeros((S, A), dtype=bool)
    for s, acts in enumerate(p.admissible_actions):
        admissible[s, acts] = True
    into_survival = np.broadcast_to(np.arange(S) == STATE_SURVIVAL, P.shape)
    if not np.array_equal(R[P > 0], into_survival[P > 0].astype(np.float64)):
        raise AocError("internal: the icu-sepsis rewards are not 1 exactly on the steps into "
                       "survival (a package version other than 2.0.1?)")
    r = np.einsum("sat,sat->sa", P, R)
    if strategy == "terminate":
        fatal = ~admissible & ~terminal[:, None]
        P = P.copy()
        P[fatal] = 0.0
        P[fatal, STATE_DEATH] = 1.0
        r = np.where(fatal, R[:, :, STATE_DEATH], r)
    obs = np.concatenate([np.asarray(p.state_cluster_centers, dtype=np.float64),
                          np.asarray(p.sofa_scores, dtype=np.float64)[:, None]], axis=1)
    return SepsisTables(strategy, TabularMDP(P, r, np.asarray(p.d_0, dtype=np.float64),
                                             terminal),
                        np.asarray(p.expert_policy, dtype=np.float64), admissible, obs)


# -- the log ------------------------------------------------------------------------------------

def _sample(cum: np.ndarray, u: np.ndarray) -> np.ndarray:
    """Row-wise inverse-CDF draws: ``cum`` (n, K) cumulative probabilities, ``u`` (n,) in
    [0, 1) -> (n,) indices."""
    idx = (cum < u[:, None] * cum[:, -1:]).sum(axis=1)
    return np.minimum(idx, cum.shape[1] - 1)


def simulate(t: SepsisTables, policy: np.ndarray, episodes: int, rng: np.random.Generator,
             progress: Progress | None = None) -> dict[str, np.ndarray]:
    """``episodes`` patients treated by ``policy`` (716, 25) in the tables' MDP, rows in episode
    order: ``state``, ``action``, ``reward``, ``propensity`` (each (N,)) and ``lengths`` (E,),
    ``terminal`` (E,) bool (False: cut at :data:`MAX_STEPS`)."""
    P = t.mdp.P
    pi_cum = np.cumsum(policy, axis=1)
    d0_cum = np.cumsum(t.mdp.d0)[None, :]
    parts, lengths, ends = [], [], []
    done_eps = 0
    for start in range(0, episodes, BATCH):
        n = min(BATCH, episodes - start)
        s = _sample(np.broadcast_to(d0_cum, (n, len(t.mdp.d0))), rng.random(n))
        alive = np.arange(n)
        cols = {"episode": [], "step": [], "state": [], "action": [], "reward": []}
        length = np.zeros(n, dtype=np.int64)
        terminal = np.zeros(n, dtype=bool)
        for step in range(MAX_STEPS):
            if len(alive) == 0:
                break
            a = _sample(pi_cum[s], rng.random(len(alive)))
            nxt = _sample(np.cumsum(P[s, a], axis=1), rng.random(len(alive)))
            reward = (nxt == STATE_SURVIVAL).astype(np.float64)
            for key, val in (("episode", alive), ("step", np.full(len(alive), step)),
                             ("state", s), ("action", a), ("reward", reward)):
                cols[key].append(val)
            length[alive] += 1
            ended = t.mdp.terminal[nxt]
            terminal[alive[ended]] = True
            alive, s = alive[~ended], nxt[~ended]
        flat = {k: np.concatenate(v) for k, v in cols.items()}
        order = np.lexsort((flat["step"], flat["episode"]))
        parts.append({k: flat[k][order] for k in ("state", "action", "reward")})
        lengths.append(length)
        ends.append(terminal)
        done_eps += n
        if progress is not None:
            progress(done_eps, episodes)
    out = {k: np.concatenate([p[k] for p in parts]) for k in ("state", "action", "reward")}
    out["propensity"] = policy[out["state"], out["action"]]
    out["lengths"] = np.concatenate(lengths)
    out["terminal"] = np.concatenate(ends)
    return out


def collect_data(steps: int | None = None, episodes: int | None = None, seed: int = 0,
                 progress: Progress | None = None, policy: str = "clinicians",
                 strategy: str = "mean", task: str = "icu-sepsis"
                 ) -> tuple[CorpusData, list[dict]]:
    """A log of ``policy`` (``clinicians`` or ``random``): ``episodes`` patients, or as many as
    hold ``steps`` rows (the last one cut to exactly that many). Same seed, same arrays."""
    if policy not in POLICIES:
        raise AocError(f"unknown policy {policy!r} for {task}: use {' or '.join(POLICIES)}")
    steps, episodes = budget(steps, episodes, None, DEFAULT_EPISODES)
    t = tables(strategy)
    pi = t.behaviour(policy)
    rng = np.random.default_rng(seed)
    if episodes is not None:
        sim = simulate(t, pi, episodes, rng, progress)
    else:  # whole episodes until the rows suffice, then cut (about 9 rows an episode)
        sims, rows = [], 0
        while rows < steps:
            sims.append(simulate(t, pi, max(64, (steps - rows) // 8 + 1), rng))
            rows += len(sims[-1]["state"])
            if progress is not None:
                progress(min(rows, steps), steps)
        sim = {k: np.concatenate([s[k] for s in sims]) for k in sims[0]}
    data = _corpus(t, sim, policy, steps)
    data.source = {"kind": "collect", "task": task, "seed": int(seed), "steps": steps,
                   "episodes": episodes, "policy": policy, "strategy": strategy}
    return data, summary(data, t, pi, policy)


def _corpus(t: SepsisTables, sim: dict, policy: str, steps: int | None) -> CorpusData:
    lengths, terminal = sim["lengths"], sim["terminal"].copy()
    if steps is not None:
        ends = np.cumsum(lengths)
        keep = int(np.searchsorted(ends, steps)) + 1
        lengths = lengths[:keep].copy()
        terminal = terminal[:keep]
        cut = int(ends[keep - 1]) - steps
        if cut:
            lengths[-1] -= cut
            terminal[-1] = False
        sim = {k: sim[k][:steps] for k in ("state", "action", "reward", "propensity")}
    starts = episode_starts_from_lengths(lengths)
    n = int(starts[-1])
    last = starts[1:] - 1
    terminals = np.zeros(n, dtype=bool)
    truncations = np.zeros(n, dtype=bool)
    terminals[last[terminal]] = True
    truncations[last[~terminal]] = True
    width = max(5, len(str(len(lengths) - 1)))
    return CorpusData(
        observations=t.observations[sim["state"]].astype(np.float32),
        actions=sim["action"].astype(np.int64),
        rewards=sim["reward"].astype(np.float64),
        terminals=terminals, truncations=truncations, episode_starts=starts,
        observation_space=box_space(len(OBS_NAMES), names=list(OBS_NAMES)),
        action_space=discrete_space(len(ACTION_NAMES), names=list(ACTION_NAMES)),
        tags={"policy": (np.full(n, POLICIES.index(policy), dtype=np.int32), list(POLICIES))},
        columns={"state": sim["state"].astype(np.float64),
                 "propensity": sim["propensity"].astype(np.float64)},
        episode_ids=[f"p{i:0{width}d}" for i in range(len(lengths))],
    ).validate()


def summary(data: CorpusData, t: SepsisTables, pi: np.ndarray, policy: str) -> list[dict]:
    """One record: the behaviour's episodes, rows, survival in the log (complete episodes) and
    its exact value."""
    starts = data.episode_starts
    complete = data.terminals[starts[1:] - 1]
    returns = np.add.reduceat(data.rewards, starts[:-1])[complete]
    return [{"policy": policy, "episodes": data.n_episodes, "rows": data.n_rows,
             "mean_return": float(returns.mean()) if len(returns) else None,
             "std_return": float(returns.std()) if len(returns) else None,
             "exact_value": t.mdp.value(pi)}]


# -- the environment ----------------------------------------------------------------------------

class SepsisObservations(gymnasium.ObservationWrapper):
    """The package's environment (flat actions 0..24) with observations = the state's 48
    numbers (:data:`OBS_NAMES`); ``info["state"]`` is the discrete state."""

    def __init__(self, env: gymnasium.Env, observations: np.ndarray):
        super().__init__(env)
        self._obs = observations.astype(np.float32)
        self.observation_space = gymnasium.spaces.Box(-np.inf, np.inf, (len(OBS_NAMES),),
                                                      np.float32)

    def reset(self, *, seed=None, options=None):
        state, info = self.env.reset(seed=seed, options=options)
        return self.observation(state), {**info, "state": int(state)}

    def step(self, action):
        state, reward, terminated, truncated, info = self.env.step(int(action))
        return self.observation(state), float(reward), terminated, truncated, \
            {**info, "state": int(state)}

    def observation(self, state):
        return self._obs[int(state)].copy()


def make_sepsis_env(strategy: str = "mean", render_mode=None) -> gymnasium.Env:
    """The package's ICU-Sepsis environment under ``strategy``, observing feature vectors."""
    package()
    from icu_sepsis.envs.sepsis import ICUSepsisEnv
    from icu_sepsis.wrappers import FlattenActionWrapper

    env = FlattenActionWrapper(ICUSepsisEnv(params=parameters(),
                                            inadmissible_action_strategy=strategy))
    return SepsisObservations(env, tables(strategy).observations)


#: The trajectory of a stay: SOFA score over its steps (``aoc collect --plot``).
_plot, _trajectory = step_series("icu-sepsis", "SOFA score", -1)


#: AOC's settings on these tasks (docs/design.md, "Support"; docs/results.md, "icu-sepsis"):
#: states repeat exactly, so a logged (state, action) decomposes with residual 0 and the cap
#: (1% of the typical p90 residual) keeps the candidates the corpus holds; of those, the best
#: by v_hat shrunk by the episodes behind it (v_hat - 5 sigma_v / sqrt(support)).
CONTROLLER = {"residual_cap": 0.01, "support_penalty": 5.0}


def _task(name: str, gym_id: str, strategy: str, description: str) -> Task:
    return Task(
        name=name, gym_id=gym_id, description=description, horizon=MAX_STEPS,
        policies=POLICIES, make_fn=lambda **kw: gymnasium.make(gym_id, **kw),
        collect_fn=lambda steps=None, episodes=None, seed=0, progress=None,
        policy="clinicians": collect_data(steps, episodes, seed, progress, policy, strategy,
                                          name),
        plot_fn=_plot, trajectory_fn=_trajectory, default_episodes=DEFAULT_EPISODES,
        extra={"strategy": strategy, "choose_policy": True,
               # what the decision page says of the values it shows (aoc_cli/report/values.py)
               "units": "the package's normalised values, not raw measurements: each state's "
                        "cluster centre, binary features minus 0.5, the others z-scored (some "
                        "after a log); sofa_score in SOFA points"},
        controller=dict(CONTROLLER),
        # Markov in its observation: the value belief reads no history, so AOC's policy is a
        # state policy (valued exactly; tests/control/test_icu_sepsis_quality.py). Each row's
        # value is the clinicians' Q by fitted Q evaluation through the log, undiscounted as
        # the task's survival is: the Monte-Carlo return-to-go is too noisy here (10k
        # episodes: validation R^2 0.02 against 0.90; docs/results.md, "icu-sepsis")
        training={"value": {"history_length": 0, "value": "fqe", "gamma": 1.0}},
    )


TASKS = [
    _task("icu-sepsis", GYM_ID, "mean",
          "ICU-Sepsis (MIMIC-III): 25 fluid x vasopressor doses, survival reward"),
    _task("icu-sepsis-terminate", GYM_ID_TERMINATE, "terminate",
          "ICU-Sepsis, an action outside the clinicians' admissible set is fatal"),
]
