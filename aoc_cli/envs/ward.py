"""ward: a simulated hospital ward, the paper's strictly batch imitation case (ABC).

No real patient data can ship; this task writes a log shaped like one. Each episode is one
patient's stay of 8-12 steps (say, 4-hourly reviews):

* **static covariates** (per patient): ``age``, ``sex`` (F/M; one-hot ``sex=F``, ``sex=M`` as a
  CSV ingest with ``--static`` makes it), ``bmi``, ``copd`` (chronic lung disease, 0/1),
  ``heart_failure`` (0/1), ``frailty`` (0-1) and ``risk_score`` (an admission early-warning
  score, noisy in the latent severity);
* **temporal vitals** (per step): ``obs_spo2`` (%), ``obs_resp_rate`` (/min), ``obs_heart_rate``
  (/min), ``obs_sbp`` (mmHg), ``obs_temp`` (C), driven by a latent lung-function deficit s_t
  that drifts (improving, stable or deteriorating patients) and **responds to the treatment**:
  oxygen given at step t raises the next SpO2 by about 4 points and lowers the respiratory rate,
  and slows the deterioration;
* **the clinicians' policy** (the behaviour; tag ``clinician``, five clinicians ``c1``..``c5``
  with their own thresholds): start oxygen when SpO2 falls below the clinician's threshold
  (88 for COPD patients, whose target range is lower) or the respiratory rate exceeds theirs;
  a patient *on* oxygen stays on it until SpO2 has recovered to the threshold + 3 (hysteresis:
  the same vitals get different decisions depending on the previous step, which only the
  history shows); for COPD patients a fall of 3 or more points since the last review also
  starts it (a trend: history again). Each decision is a logistic choice around these rules
  (noise), so the same patient state does not always get the same decision;
* a rare binary action ``act_oxygen`` (about 10% of steps), no rewards (reward-free, like a
  clinical log), and a numeric per-row column ``outcome``: 1 when the patient's deficit at
  discharge exceeds :data:`ICU_DEFICIT` (transfer to intensive care), else 0.

:func:`write_csv` writes the steps and the static table as the two CSV files of a real log;
:func:`collect_data` reads them back with the CSV reader (exactly what ``aoc ingest
--static`` does), so a collected corpus and an ingested one are the same arrays.
"""

from __future__ import annotations

import csv
import tempfile
from pathlib import Path

import gymnasium
import numpy as np
from gymnasium import spaces

from aoc_cli.envs.base import Progress, Task, budget
from aoc_cli.envs.render import step_series
from aoc_cli.errors import BadSetting, param
from aoc_cli.formats import ReadOptions, read_dataset
from aoc_cli.store import CorpusData, atomic_path

GYM_ID = "aoc/Ward-v0"
STAY = (8, 12)
CLINICIANS = ("c1", "c2", "c3", "c4", "c5")
#: Per clinician: (SpO2 threshold, respiratory-rate threshold, decision noise (logistic scale)).
CLINICIAN_RULES = {"c1": (91.0, 25.0, 0.3), "c2": (90.0, 26.0, 0.35), "c3": (92.0, 24.0, 0.3),
                   "c4": (89.0, 27.0, 0.4), "c5": (91.0, 25.0, 0.5)}
COPD_SPO2 = 88.0
WEAN_MARGIN = 3.0
TREND_DROP = 3.0
ICU_DEFICIT = 4.5
VITALS = ("obs_spo2", "obs_resp_rate", "obs_heart_rate", "obs_sbp", "obs_temp")
STATIC = ("age", "sex", "bmi", "copd", "heart_failure", "frailty", "risk_score")
#: Observation names as a CSV ingest with --static writes them (text columns one-hot).
OBS_NAMES = list(VITALS) + ["age", "sex=F", "sex=M", "bmi", "copd", "heart_failure",
                            "frailty", "risk_score"]
DEFAULT_EPISODES = 500


# -- patients and their vitals ------------------------------------------------------------------

def new_patients(n: int, rng: np.random.Generator) -> dict[str, np.ndarray]:
    """Static covariates and the hidden state of ``n`` patients (each (n,))."""
    age = np.clip(rng.normal(66.0, 15.0, n), 18.0, 98.0).round()
    female = rng.random(n) < 0.5
    bmi = np.clip(rng.normal(27.0, 5.0, n), 15.0, 50.0).round(1)
    copd = (rng.random(n) < 0.2).astype(np.float64)
    heart_failure = (rng.random(n) < 0.15 + 0.002 * (age - 66.0)).astype(np.float64)
    frailty = np.clip(rng.beta(2.0, 5.0, n) + 0.004 * (age - 66.0), 0.0, 1.0).round(2)
    deficit = np.clip(rng.gamma(2.0, 0.45, n) + 0.8 * copd + 0.5 * heart_failure, 0.0, None)
    # improving (-0.35 a step), stable (0) or deteriorating (+0.45), frailer patients worse
    kind = rng.choice(3, size=n, p=[0.4, 0.4, 0.2])
    drift = np.array([-0.35, 0.0, 0.45])[kind] + 0.3 * frailty
    risk = np.clip(np.round(deficit + 0.02 * (age - 66.0) + rng.normal(0.0, 0.7, n), 1), 0, None)
    return {"age": age, "female": female.astype(np.float64), "bmi": bmi, "copd": copd,
            "heart_failure": heart_failure, "frailty": frailty, "risk_score": risk,
            "deficit": deficit, "drift": drift,
            "length": rng.integers(STAY[0], STAY[1] + 1, n)}


def vitals(p: dict, deficit: np.ndarray, on_oxygen: np.ndarray,
           rng: np.random.Generator) -> np.ndarray:
    """(n, 5) vitals of patients with latent ``deficit`` (n,), ``on_oxygen`` (n,) 0/1 (the
    previous step's treatment)."""
    n = len(deficit)
    spo2 = 98.5 - 2.2 * deficit - 3.0 * p["copd"] + 4.0 * on_oxygen + rng.normal(0.0, 1.0, n)
    rr = 15.0 + 2.2 * deficit - 2.5 * on_oxygen + rng.normal(0.0, 1.3, n)
    hr = 72.0 + 4.0 * deficit + 6.0 * p["heart_failure"] + rng.normal(0.0, 6.0, n)
    sbp = 128.0 - 2.0 * deficit + 0.2 * (p["age"] - 66.0) + rng.normal(0.0, 9.0, n)
    temp = 36.9 + 0.25 * deficit + rng.normal(0.0, 0.3, n)
    return np.stack([np.clip(spo2, 70.0, 100.0).round(), rr.round(), hr.round(), sbp.round(),
                     temp.round(1)], axis=1)


def clinician_decision(obs: np.ndarray, previous_obs: np.ndarray | None,
                       previous_action: np.ndarray, copd: np.ndarray, clinician: np.ndarray,
                       rng: np.random.Generator) -> np.ndarray:
    """(n,) 0/1 oxygen decisions from the vitals (n, 5), the previous review's vitals (or
    None at admission) and action (n,), COPD (n,) and the clinicians' indices (n,)."""
    rules = np.array([CLINICIAN_RULES[c] for c in CLINICIANS])[clinician]
    spo2_thr = np.where(copd > 0, COPD_SPO2, rules[:, 0])
    rr_thr, noise = rules[:, 1], rules[:, 2]
    spo2, rr = obs[:, 0], obs[:, 1]
    start = np.maximum(spo2_thr - spo2, (rr - rr_thr) / 2.0)   # > 0: start oxygen
    if previous_obs is not None:
        drop = previous_obs[:, 0] - spo2
        trend = np.maximum(start, 0.5 + drop - TREND_DROP)
        start = np.where((copd > 0) & (drop >= TREND_DROP), trend, start)
    keep = spo2_thr + WEAN_MARGIN - spo2 + 0.5                 # > 0: stay on oxygen
    score = np.where(previous_action > 0, keep, start)
    p = 1.0 / (1.0 + np.exp(-score / noise))
    return (rng.random(len(spo2)) < p).astype(np.int64)


def simulate(n: int, seed: int, progress: Progress | None = None) -> dict:
    """``n`` patient stays: a dict of per-row arrays (``patient``, ``hour``, vitals, ``oxygen``,
    ``clinician``, ``outcome``) and the static table (``static``: one entry per patient)."""
    rng = np.random.default_rng(seed)
    p = new_patients(n, rng)
    clinician = rng.integers(0, len(CLINICIANS), n)
    length = p["length"]
    T = int(length.max())
    deficit = p["deficit"].copy()
    prev_action = np.zeros(n, np.int64)
    prev_obs = None
    obs_t, act_t = np.zeros((T, n, len(VITALS))), np.zeros((T, n), np.int64)
    after = np.zeros((T, n))  # the deficit after each step's decision took effect
    for t in range(T):
        obs = vitals(p, deficit, prev_action.astype(np.float64), rng)
        action = clinician_decision(obs, prev_obs, prev_action, p["copd"], clinician, rng)
        obs_t[t], act_t[t] = obs, action
        deficit = np.clip(deficit + p["drift"] - 0.35 * action + rng.normal(0.0, 0.35, n),
                          0.0, None)
        after[t] = deficit
        prev_obs, prev_action = obs, action
        if progress is not None:
            progress(t + 1, T)
    final = after[length - 1, np.arange(n)]  # the deficit at discharge
    outcome = (final > ICU_DEFICIT).astype(np.int64)
    mask = np.arange(T)[:, None] < length[None, :]                 # (T, n)
    pat, hour = np.nonzero(mask.T)                                  # rows patient-major
    ids = np.array([f"p{i:04d}" for i in range(n)])
    rows = {"patient": ids[pat], "hour": hour * 4}
    for j, name in enumerate(VITALS):
        rows[name] = obs_t[hour, pat, j]
    rows["act_oxygen"] = act_t[hour, pat]
    rows["clinician"] = np.array(CLINICIANS)[clinician[pat]]
    rows["outcome"] = outcome[pat]
    static = {"patient": ids, "age": p["age"], "sex": np.where(p["female"] > 0, "F", "M"),
              "bmi": p["bmi"], "copd": p["copd"], "heart_failure": p["heart_failure"],
              "frailty": p["frailty"], "risk_score": p["risk_score"]}
    return {"rows": rows, "static": static}


# -- the log as CSV files, and as a corpus ------------------------------------------------------

def _fmt(v) -> str:
    if isinstance(v, (float, np.floating)):
        return f"{float(v):g}"
    return str(v)


def write_table(path: Path, table: dict[str, np.ndarray]) -> None:
    """One CSV file of the columns ``table`` (name -> (n,) array), written atomically."""
    names = list(table)
    with atomic_path(path, suffix=".csv") as tmp:
        with open(tmp, "w", newline="") as fh:
            w = csv.writer(fh, lineterminator="\n")
            w.writerow(names)
            for i in range(len(table[names[0]])):
                w.writerow([_fmt(table[c][i]) for c in names])


def write_csv(out_dir, name: str = "ward", episodes: int = DEFAULT_EPISODES, seed: int = 0,
              progress: Progress | None = None) -> tuple[Path, Path]:
    """Write ``<out_dir>/<name>.csv`` (one row per step: patient, hour, vitals, act_oxygen,
    clinician, outcome) and ``<out_dir>/<name>-static.csv`` (one row per patient), atomically.
    Returns the two paths."""
    if episodes <= 0:
        raise BadSetting("episodes", episodes,
                         f"{param('episodes')} must be a positive integer, got {episodes}")
    sim = simulate(int(episodes), int(seed), progress)
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    steps, static = out / f"{name}.csv", out / f"{name}-static.csv"
    write_table(steps, sim["rows"])
    write_table(static, sim["static"])
    return steps, static


def read_options(static: Path):
    """The ingest options that read the two files (as the README's ``aoc ingest`` line)."""
    return ReadOptions(id_column="patient", time_column="hour", static=Path(static),
                       discrete_actions=True, tag_columns=["clinician"], reward_free=True)


def collect_data(steps: int | None = None, episodes: int | None = None, seed: int = 0,
                 progress: Progress | None = None) -> tuple[CorpusData, list[dict]]:
    """``episodes`` patient stays (or as many as hold ``steps`` rows, cut to exactly that
    many), written as CSV and read back as ``aoc ingest --static`` reads them."""
    steps, episodes = budget(steps, episodes, None, DEFAULT_EPISODES)
    n = episodes if episodes is not None else int(np.ceil(steps / STAY[0]))
    with tempfile.TemporaryDirectory(prefix=".aoc-ward-") as tmp:
        csv_path, static_path = write_csv(tmp, "ward", n, seed, progress)
        data = read_dataset(csv_path, options=read_options(static_path))
    if steps is not None:
        keep_eps = int(np.searchsorted(data.episode_starts, steps, side="left"))
        data = data.select_episodes(np.arange(data.n_episodes) < keep_eps)
        if data.n_rows > steps:  # the last kept stay cut short (truncated)
            data = _cut(data, steps)
    data.source = {"kind": "collect", "task": "ward", "seed": int(seed), "steps": steps,
                   "episodes": episodes}
    return data, summary(data)


def _cut(data: CorpusData, steps: int) -> CorpusData:
    keep = slice(0, steps)
    starts = data.episode_starts.copy()
    starts[-1] = steps
    terminals, truncations = data.terminals[keep].copy(), data.truncations[keep].copy()
    terminals[-1], truncations[-1] = False, True
    return CorpusData(
        observations=data.observations[keep], actions=data.actions[keep], rewards=None,
        terminals=terminals, truncations=truncations, episode_starts=starts,
        observation_space=data.observation_space, action_space=data.action_space,
        tags={k: (c[keep], lab) for k, (c, lab) in data.tags.items()},
        columns={k: v[keep] for k, v in data.columns.items()},
        episode_ids=data.episode_ids, source=data.source)


def summary(data: CorpusData) -> list[dict]:
    """Per clinician: patients, rows, the share of steps with oxygen, the ICU-transfer rate."""
    codes, labels = data.tags["clinician"]
    first = data.episode_starts[:-1]
    out = []
    for i, label in enumerate(labels):
        rows = codes == i
        eps = codes[first] == i
        out.append({"clinician": label, "episodes": int(eps.sum()), "rows": int(rows.sum()),
                    "treated_share": float(np.mean(data.actions[rows])) if rows.any() else None,
                    "icu_rate": float(np.mean(data.columns["outcome"][first][eps]))
                    if eps.any() else None})
    return out


# -- a gymnasium environment: one patient a episode ---------------------------------------------

class WardEnv(gymnasium.Env):
    """One patient's stay: observation = the vitals then the static covariates (as
    :data:`OBS_NAMES`), action 0/1 (oxygen), reward 0 (the log is reward-free);
    ``info["outcome"]`` at the last step: 1 on a transfer to intensive care."""

    metadata = {"render_modes": []}

    def __init__(self, render_mode=None):
        self.observation_space = spaces.Box(-np.inf, np.inf, shape=(len(OBS_NAMES),),
                                            dtype=np.float32)
        self.action_space = spaces.Discrete(2)

    def reset(self, *, seed=None, options=None):
        super().reset(seed=seed)
        self.p = new_patients(1, self.np_random)
        self.deficit = self.p["deficit"].copy()
        self.t = 0
        self.on = np.zeros(1)
        return self._obs(), {"outcome": None}

    def _obs(self) -> np.ndarray:
        v = vitals(self.p, self.deficit, self.on, self.np_random)[0]
        p = self.p
        static = [p["age"][0], p["female"][0], 1.0 - p["female"][0], p["bmi"][0], p["copd"][0],
                  p["heart_failure"][0], p["frailty"][0], p["risk_score"][0]]
        return np.concatenate([v, static]).astype(np.float32)

    def step(self, action):
        a = float(int(np.asarray(action).reshape(-1)[0]) > 0)
        self.deficit = np.clip(self.deficit + self.p["drift"] - 0.35 * a
                               + self.np_random.normal(0.0, 0.35, 1), 0.0, None)
        self.on = np.array([a])
        self.t += 1
        done = self.t >= int(self.p["length"][0])
        info = {"outcome": int(self.deficit[0] > ICU_DEFICIT) if done else None}
        return self._obs(), 0.0, done, False, info


#: The trajectory of a stay: SpO2 (%) over its steps (``aoc collect --plot``).
_plot, _trajectory = step_series("ward", "SpO2 (%)", 0)


TASKS = [Task(
    name="ward", gym_id=GYM_ID,
    description="simulated hospital ward: oxygen decisions of five clinicians, reward-free",
    horizon=STAY[1], policies=CLINICIANS, make_fn=lambda **kw: gymnasium.make(GYM_ID, **kw),
    collect_fn=collect_data, plot_fn=_plot, trajectory_fn=_trajectory,
    default_episodes=DEFAULT_EPISODES, extra={"write_csv": write_csv, "reward_free": True},
)]
