"""icu-cohort: the cohort table drawn from the ICU-Sepsis MDP, its ingest with the short
command, the environment that replays the MDP through the same noisy features, and the
Monte-Carlo true survival against the exact values."""

import importlib.util
import json
from pathlib import Path

import numpy as np
import pytest

from aoc_cli.envs import collect, make_env, task_settings
from aoc_cli.envs import icu_cohort as ic
from aoc_cli.envs import icu_sepsis as sepsis
from aoc_cli.errors import AocError
from aoc_cli.store import Store

ROOT = Path(__file__).resolve().parents[2]
#: The user's command (docs/guide/tasks.md): no role flag, the columns' names say them.
INGEST = ["--discrete-actions", "--impute", "hold", "--outcome", "died_in_hosp",
          "--outcome-reward", "1=0,0=1"]


@pytest.fixture(scope="module")
def table():
    return ic.cohort_table(1500, seed=4)


def _script():
    spec = importlib.util.spec_from_file_location("icu_cohort_script",
                                                  ROOT / "scripts" / "icu_cohort.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def _firsts(ids):
    first = np.ones(len(ids), dtype=bool)
    first[1:] = ids[1:] != ids[:-1]
    return first


def test_the_table_first_step_measured_gaps_censoring_and_truth(table):
    ids, state = table[ic.ID], table["state"]
    first = _firsts(ids)
    assert first.sum() == 1500 and np.array_equal(np.unique(ids), ic.FIRST_ID + np.arange(1500))
    assert np.array_equal(table[ic.TIME][first], np.ones(1500))
    assert np.all(np.diff(table[ic.TIME])[~first[1:]] == 1)
    feats = np.stack([table[c] for c in ic.OBS_COLUMNS], axis=1)
    assert feats.dtype == np.float32 and feats.shape[1] == 47
    empty = np.isnan(feats)
    assert not empty[first].any()  # the admission panel: always fully measured
    share, m = empty[~first].mean(), empty[~first].size
    assert abs(share - 0.15) < 5 * np.sqrt(0.15 * 0.85 / m) + 0.002
    # the features are the true state's cluster centre plus noise of sd 0.3
    resid = (feats - ic.centres()[state])[~empty]
    assert abs(resid.std() - 0.3) < 0.005 and abs(resid.mean()) < 0.005
    assert state.max() < sepsis.STATE_DEATH
    # the logged dose is the clinicians' in the true state, with its propensity
    t = sepsis.tables()
    np.testing.assert_array_equal(table["propensity"], t.clinicians[state, table[ic.ACTION]])
    assert table["propensity"].min() > 0 and table[ic.ACTION].max() <= 24
    # one outcome per stay; the censored share; survival as the clinicians' exact value
    died = table[ic.OUTCOME]
    stay = np.cumsum(first) - 1
    out = died[first]
    assert np.array_equal(np.isnan(died), np.isnan(out)[stay])
    assert np.array_equal(died[~np.isnan(died)], out[stay][~np.isnan(died)])
    censored = np.isnan(out).mean()
    assert abs(censored - 0.03) < 5 * np.sqrt(0.03 * 0.97 / 1500)
    survival = 1 - np.nanmean(out)
    assert abs(survival - ic.clinicians_value()) < 4 * np.sqrt(0.2 / 1500) + 0.01


def test_same_seed_same_table_other_seed_other_table():
    a, b, c = (ic.cohort_table(60, seed=s) for s in (1, 1, 2))
    for k in a:
        np.testing.assert_array_equal(a[k], b[k])
    assert len(a[ic.ID]) != len(c[ic.ID]) or not np.array_equal(a["state"], c["state"])
    zero = ic.cohort_table(60, noise=0.0, gap=0.0, censored=0.0, seed=1)
    feats = np.stack([zero[c] for c in ic.OBS_COLUMNS], axis=1)
    np.testing.assert_array_equal(feats, ic.centres()[zero["state"]].astype(np.float32))
    assert not np.isnan(zero[ic.OUTCOME]).any()
    with pytest.raises(AocError, match="gap must be in"):
        ic.cohort_table(10, gap=1.5)


def test_the_csv_ingests_with_the_short_command_as_collect_logs_it(tmp_path, aoc, store):
    path = tmp_path / "cohort.csv"
    _script().main([str(path), "--stays", "800", "--seed", "3", "--truth",
                    str(tmp_path / "truth.csv")])
    header = path.read_text().splitlines()[0].split(",")
    assert header[:3] == ["id", "time", "obs_gender"] and header[-2:] == ["act_dose",
                                                                           "died_in_hosp"]
    assert len(header) == 51 and "state" not in header
    code, out, err = aoc("ingest", str(path), "--name", "c", *INGEST, "-f", "json")
    assert code == 0, err
    summary = json.loads(out)
    cols = ic.cohort_table(800, seed=3)
    first = _firsts(cols[ic.ID])
    censored = int(np.isnan(cols[ic.OUTCOME][first]).sum())
    assert summary["rows"] == len(cols[ic.ID]) and summary["episodes"] == 800
    assert summary["censored_episodes"] == censored > 0
    # the filled cells: the empty ones, about 15% of the cells after the first step
    filled = sum(summary["imputed_cells"].values())
    assert filled == sum(int(np.isnan(cols[c]).sum()) for c in ic.OBS_COLUMNS)
    assert abs(filled / ((~first).sum() * 47) - 0.15) < 0.005
    corpus = Store(store).corpus("c").load()
    assert corpus.action_space["type"] == "discrete" and corpus.action_space["n"] == 25
    assert corpus.observation_space["names"] == list(ic.OBS_COLUMNS)
    # the same log as `aoc collect icu-cohort` with that seed (the CSV keeps every float32)
    data, _ = collect("icu-cohort", episodes=800, seed=3)
    np.testing.assert_array_equal(corpus.observations.astype(np.float32), data.observations)
    for key in ("actions", "rewards", "episode_starts", "terminals", "truncations"):
        np.testing.assert_array_equal(getattr(corpus, key), getattr(data, key), err_msg=key)
    assert corpus.episode_ids == data.episode_ids
    truth = (tmp_path / "truth.csv").read_text().splitlines()
    assert truth[0] == "id,time,state,propensity" and len(truth) == len(cols[ic.ID]) + 1


def test_collect_logs_the_held_features_rewards_and_truncations():
    data, summary = collect("icu-cohort", episodes=300, seed=5)
    cols = ic.cohort_table(300, seed=5)
    starts, last = data.episode_starts, data.episode_starts[1:] - 1
    assert data.n_episodes == 300 and data.observations.shape[1] == 47
    assert not np.isnan(data.observations).any()
    raw = np.stack([cols[c] for c in ic.OBS_COLUMNS], axis=1)
    measured = ~np.isnan(raw)
    np.testing.assert_array_equal(data.observations[measured], raw[measured])
    rows, cells = np.nonzero(~measured)  # an empty cell holds the row before's value
    np.testing.assert_array_equal(data.observations[rows, cells],
                                  data.observations[rows - 1, cells])
    assert not np.isin(rows, starts[:-1]).any()
    survived = data.rewards[last] == 1
    assert np.all(data.rewards[np.setdiff1d(np.arange(data.n_rows), last)] == 0)
    assert np.array_equal(data.terminals[last], ~data.truncations[last])
    assert not (survived & data.truncations[last]).any()
    assert data.truncations[last].sum() == np.isnan(cols[ic.OUTCOME][_firsts(cols[ic.ID])]).sum()
    np.testing.assert_array_equal(data.columns["state"], cols["state"])
    assert summary[0]["exact_value"] == pytest.approx(0.7818, abs=1e-4)
    cut, _ = collect("icu-cohort", steps=333, seed=5)
    assert cut.n_rows == 333 and cut.truncations[-1] and not cut.terminals[-1]
    ends = cut.episode_starts[1:] - 1
    assert (cut.terminals[ends] | cut.truncations[ends]).all()
    assert cut.terminals.sum() + cut.truncations.sum() == cut.n_episodes


def test_the_env_at_noise_zero_observes_the_centre_and_seeds_reproduce():
    env = make_env("icu-cohort:noise=0,gap=0.5")
    assert env.spec.max_episode_steps == 500
    C = ic.centres().astype(np.float32)
    obs, info = env.reset(seed=11)
    np.testing.assert_array_equal(obs, C[info["state"]])
    env.action_space.seed(0)
    done, held, cells = False, 0, 0
    while not done:
        prev = obs
        obs, reward, term, trunc, info = env.step(env.action_space.sample())
        done = term or trunc
        # each cell the current state's centre, or (a gap) the value observed the step before
        fresh = obs == C[info["state"]]
        assert (fresh | (obs == prev)).all()
        held += (~fresh).sum()
        cells += obs.size
        assert reward == float(info["state"] == sepsis.STATE_SURVIVAL)
    assert term == (info["state"] in (713, 714, 715))
    assert 0 < held < cells

    def episode(seed):
        e = make_env("icu-cohort")
        out = [e.reset(seed=seed)[0]]
        for a in [3, 7, 0, 12, 24, 1] * 3:
            o, _, term, trunc, _ = e.step(a)
            out.append(o)
            if term or trunc:
                break
        return np.stack(out)

    np.testing.assert_array_equal(episode(5), episode(5))
    a, b = episode(5), episode(6)
    assert a.shape != b.shape or not np.array_equal(a, b)


def test_the_env_noise_and_holds():
    env = make_env("icu-cohort:noise=1.0,gap=0.15")
    assert env.unwrapped.noise == 1.0 and env.unwrapped.gap == 0.15
    C, modal = ic.centres(), sepsis.tables().modal()
    held = fresh = 0
    resid = []
    for seed in range(40):
        obs, info = env.reset(seed=seed)
        resid.append(obs - C[info["state"]])  # the first step: every cell fresh
        assert info["measured"].all()
        done = False
        while not done:
            nxt, _, term, trunc, info = env.step(int(modal[info["state"]]))
            done = term or trunc
            same = nxt == obs
            assert (info["measured"] == ~same).all()      # what it says it held, it held
            held += same.sum()
            fresh += (~same).sum()
            obs = nxt
    assert abs(np.concatenate(resid).std() - 1.0) < 0.05
    assert abs(held / (held + fresh) - 0.15) < 0.02


def test_settings_of_a_task_and_the_bad_ones():
    assert task_settings("icu-cohort:noise=1.0,gap=0.2") == ("icu-cohort",
                                                             {"noise": 1.0, "gap": 0.2})
    assert task_settings("aoc_cli.envs:aoc/Maze-v0") == ("aoc_cli.envs:aoc/Maze-v0", {})
    with pytest.raises(AocError, match=r"'nois=1' is not a setting of 'icu-cohort'.*noise, gap"):
        make_env("icu-cohort:nois=1")
    with pytest.raises(AocError, match="noise='x' is not a number"):
        make_env("icu-cohort:noise=x")
    with pytest.raises(AocError, match="noise must be a finite number >= 0"):
        make_env("icu-cohort:noise=-1")
    with pytest.raises(AocError, match="'maze' takes no settings"):
        make_env("maze:noise=1")


def test_monte_carlo_survival_matches_the_exact_values_at_noise_zero():
    """At noise 0 the nearest centre is the state: the Monte-Carlo survival of a state policy
    applied through it is the policy's exact value, within the interval."""
    t = sepsis.tables()
    modal = t.modal()
    for policy, exact, seed in ((t.clinicians, ic.clinicians_value(), 1),
                                (modal, t.mdp.value(modal), 2)):
        got = ic.rollout_value(ic.nearest_centre_policy(policy, seed=seed), 3000, noise=0.0,
                               gap=0.15, seed=seed)
        assert got["episodes"] == 3000 and got["low"] < got["value"] < got["high"]
        assert got["low"] <= exact <= got["high"], (got, exact)
    assert ic.clinicians_value() == pytest.approx(0.7818, abs=1e-4)


def test_the_nearest_centre_is_the_state_at_noise_0_3(table):
    first = _firsts(table[ic.ID])
    feats = np.stack([table[c] for c in ic.OBS_COLUMNS], axis=1)[first]
    assert (ic.nearest_state(feats) == table["state"][first]).mean() > 0.999
    with pytest.raises(AocError, match="decide_batch gave"):
        ic.rollout_value(lambda obs: np.full(len(obs), 25), 10)


def test_rollouts_meet_the_same_patients_whatever_the_policy_does():
    """Common random numbers: episode i's draws depend on (seed, step) alone, so a policy
    that differs from another at a few states changes only the episodes that reach them, and
    the paired difference is far tighter than two independent values."""
    t = ic.sepsis.tables("mean")
    modal = t.modal()
    other = modal.copy()
    other[:50] = (other[:50] + 1) % 25          # another dose in 50 of the 716 states
    a = ic.rollout_value(ic.nearest_centre_policy(modal), 3000, noise=0.3, seed=5)
    again = ic.rollout_value(ic.nearest_centre_policy(modal), 3000, noise=0.3, seed=5)
    b = ic.rollout_value(ic.nearest_centre_policy(other), 3000, noise=0.3, seed=5)
    assert (a["survived"] == again["survived"]).all()
    same = ic.paired_difference(a["survived"], again["survived"])
    assert same["difference"] == 0.0 and same["low"] == same["high"] == 0.0
    d = ic.paired_difference(b["survived"], a["survived"])
    assert 0.0 < d["differ"] < 0.2                      # most patients' courses are the same
    assert d["difference"] == pytest.approx(b["value"] - a["value"], abs=1e-12)
    assert d["high"] - d["low"] < b["high"] - b["low"]   # tighter than one value's interval
    with pytest.raises(AocError):
        ic.paired_difference(np.ones(1), np.ones(1))
