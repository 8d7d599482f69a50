"""A stay cut short (censored at ingest) is continued past its cut in the value targets, not
read as an outcome of 0; a time-limit truncation of a simulator keeps its plain return."""

import numpy as np
import pytest

import aoc_cli
from aoc_cli.belief.censoring import cut_values
from aoc_cli.belief.targets import discounted_return_to_go, value_targets
from aoc_cli.store import Store
from tests.formats.cohorts import cohort, roles, write


def test_cut_value_is_the_mean_of_the_uncensored_stays_present_at_that_step():
    # stays: complete (length 3), complete (length 2), censored after 2 steps
    starts = np.array([0, 3, 5, 7])
    values = np.array([1.0, 2.0, 3.0, 10.0, 20.0, 0.0, 0.0])
    censored = np.array([False, False, True])
    # at step 2 only the first stay is still there: its row at step 2 holds 3.0
    assert cut_values(values, starts, censored).tolist() == [0.0, 0.0, 3.0]
    # cut after 4 steps: no complete stay reached step 4 -> their last rows (3.0, 20.0)
    starts = np.array([0, 3, 5, 9])
    values = np.r_[values[:5], np.zeros(4)]
    assert cut_values(values, starts, censored)[2] == pytest.approx(11.5)


def test_return_targets_continue_censored_stays_and_leave_the_others(tmp_path):
    store = Store(tmp_path / "s")
    cols = cohort(stays=60, censored=0.15, gap=0.0)
    path = write(cols, tmp_path / "c.csv")
    aoc_cli.ingest(path, "icu", store=store, options=roles(
        act_columns=["input_4hourly"], outcome="died_in_hosp", outcome_reward="1=-1,0=1"))
    c = store.corpus("icu")
    gamma = 0.9
    v = value_targets(c, "return", gamma)
    plain = discounted_return_to_go(c.rewards, c.episode_starts, gamma)
    starts = c.episode_starts
    last = starts[1:] - 1
    cut = c.read("truncations")[last]
    assert cut.any()
    rows_cut = np.repeat(cut, np.diff(starts))
    np.testing.assert_array_equal(v[~rows_cut], plain[~rows_cut])
    assert (plain[rows_cut] == 0).all() and (v[rows_cut] != 0).all()
    e = int(np.flatnonzero(cut)[0])
    expect = cut_values(plain, starts, cut)[e]
    assert v[last[e]] == pytest.approx(gamma * expect)
    assert -1 <= expect <= 1


def test_without_recorded_censoring_a_truncation_keeps_its_plain_return(tmp_path):
    store = Store(tmp_path / "s")
    cols = cohort(stays=20, gap=0.0)
    cols["terminal"] = np.zeros(len(cols["bloc"]))
    cols["reward"] = np.ones(len(cols["bloc"]))
    path = write(cols, tmp_path / "c.csv")
    aoc_cli.ingest(path, "sim", store=store, options=roles(
        act_columns=["input_4hourly"], terminal_column="terminal"))
    c = store.corpus("sim")
    assert c.read("truncations")[c.episode_starts[1:] - 1].all()
    np.testing.assert_array_equal(value_targets(c, "return", 0.9),
                                  discounted_return_to_go(c.rewards, c.episode_starts, 0.9))


def test_fqe_bootstraps_a_censored_stays_cut_from_the_stays_present_there():
    """Two complete stays A -> B (B pays 1 then ends), and a stay cut after A (state C, action
    0, reward 0, censored): uncensored, Q(C, 0) would be 0; censored, its cut is continued by
    the complete stays' rows at step 1 (B, Q = 1): Q(C, 0) = gamma * 1."""
    from aoc_cli.belief.fqe import FQEConfig, fitted_q_values

    a, b, c = [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]
    obs = np.array([a, b, a, b, c], np.float32)
    act = np.zeros(5, np.int64)
    rew = np.array([0.0, 1.0, 0.0, 1.0, 0.0])
    starts = np.array([0, 2, 4, 5])
    small = FQEConfig(iterations=6, steps=150, hidden=32, final_iterations=2)
    plain = fitted_q_values(obs, act, rew, starts, 0.9, n_actions=1, config=small)
    cut = fitted_q_values(obs, act, rew, starts, 0.9, n_actions=1, config=small,
                          censored=np.array([False, False, True]))
    assert abs(plain[4]) < 0.05 and abs(cut[4] - 0.9) < 0.05
    np.testing.assert_allclose(cut[:4], plain[:4], atol=0.05)
