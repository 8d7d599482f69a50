"""The ward task: a clinical-shaped log, its CSV form and the behaviour it encodes."""

import numpy as np
from typer.testing import CliRunner

from aoc_cli.cli.app import app
from aoc_cli.envs import collect, make_env
from aoc_cli.envs.ward import OBS_NAMES, read_options, write_csv
from aoc_cli.formats import read_dataset


def test_collected_ward_is_what_ingest_reads_from_its_csv(tmp_path):
    data, summary = collect("ward", episodes=60, seed=3)
    steps, static = write_csv(tmp_path, "ward", episodes=60, seed=3)
    read = read_dataset(steps, options=read_options(static))
    np.testing.assert_array_equal(data.observations, read.observations)
    np.testing.assert_array_equal(data.actions, read.actions)
    assert data.episode_ids == read.episode_ids and data.episode_ids[0] == "p0000"
    assert data.rewards is None and data.discrete and data.action_space["n"] == 2
    assert data.observation_space["names"] == OBS_NAMES
    assert data.observation_space["static"] == OBS_NAMES[5:]
    assert sorted(data.tags) == ["clinician"] and "outcome" in data.columns
    assert sum(r["episodes"] for r in summary) == 60
    lengths = np.diff(data.episode_starts)
    assert lengths.min() >= 8 and lengths.max() <= 12


def test_treatment_is_rare_responds_to_vitals_and_depends_on_the_previous_step():
    data, _ = collect("ward", episodes=1500, seed=0)
    a = data.actions
    assert 0.05 <= a.mean() <= 0.15
    spo2 = data.observations[:, 0]
    assert a[spo2 < 88].mean() > 0.8 and a[spo2 > 95].mean() < 0.05
    # hysteresis: at the same SpO2, a patient already on oxygen keeps it far more often
    first = np.zeros(len(a), bool)
    first[data.episode_starts[:-1]] = True
    prev = np.r_[0, a[:-1]]
    band = (~first) & (spo2 >= 92) & (spo2 <= 93)
    on, off = band & (prev == 1), band & (prev == 0)
    assert on.sum() > 20 and off.sum() > 20
    assert a[on].mean() > a[off].mean() + 0.4
    # oxygen raises the next SpO2
    nxt = np.r_[spo2[1:], 0]
    last = np.zeros(len(a), bool)
    last[data.episode_starts[1:] - 1] = True
    deficit_proxy = spo2 < 91
    gain_on = (nxt - spo2)[~last & deficit_proxy & (a == 1)].mean()
    gain_off = (nxt - spo2)[~last & deficit_proxy & (a == 0)].mean()
    assert gain_on > gain_off + 1.0


def test_collect_steps_is_exact_and_the_env_runs():
    data, _ = collect("ward", steps=95, seed=1)
    assert data.n_rows == 95 and data.truncations[-1]
    env = make_env("ward")
    obs, _ = env.reset(seed=0)
    assert obs.shape == (len(OBS_NAMES),) and env.observation_space.contains(obs)
    done, t = False, 0
    while not done:
        obs, r, done, trunc, info = env.step(1)
        done = done or trunc
        t += 1
    assert 8 <= t <= 12 and info["outcome"] in (0, 1) and r == 0.0


def test_collect_csv_writes_the_two_files(tmp_path):
    res = CliRunner().invoke(app, ["--store", str(tmp_path / "store"), "collect", "ward",
                                   "--name", "w", "--episodes", "20", "--csv",
                                   str(tmp_path / "out")])
    assert res.exit_code == 0, res.output
    head = (tmp_path / "out" / "w.csv").read_text().splitlines()[0].split(",")
    assert head[:2] == ["patient", "hour"] and "act_oxygen" in head
    static = (tmp_path / "out" / "w-static.csv").read_text().splitlines()
    assert static[0].startswith("patient,age,sex") and len(static) == 21
