"""--value fqe: fitted Q evaluation of the logged behaviour, against Q values computed by hand."""

from dataclasses import replace

import numpy as np
import pytest

from aoc_cli.belief.fqe import FQEConfig, fitted_q_values, next_rows
from aoc_cli.belief.targets import value_spec, value_targets
from aoc_cli.errors import AocError
from aoc_cli.store import CorpusData, Store, box_space, discrete_space, episode_starts_from_lengths

SMALL = FQEConfig(iterations=6, steps=150, hidden=32, final_iterations=2)


def two_step_log():
    """States A (obs [1, 0]) and B (obs [0, 1]); the behaviour's Q by hand (gamma 1):
    B: action 0 pays 1 (3 episodes), action 1 pays 0 (1 episode), so Q(B, 0) = 1, Q(B, 1) = 0;
    A: action 1 pays 0.2 and ends; action 0 pays 0 and leads to B, whose logged next actions are
    0, 0, 0, 1: Q(A, 0) = (1 + 1 + 1 + 0) / 4 = 0.75, not what one episode's return says."""
    a_obs, b_obs = [1.0, 0.0], [0.0, 1.0]
    episodes = [[(a_obs, 0, 0.0), (b_obs, 0, 1.0)]] * 3 + [[(a_obs, 0, 0.0), (b_obs, 1, 0.0)]] + \
        [[(a_obs, 1, 0.2)]] * 2
    rows = [step for ep in episodes for step in ep]
    obs = np.array([r[0] for r in rows], np.float32)
    act = np.array([r[1] for r in rows], np.int64)
    rew = np.array([r[2] for r in rows])
    starts = episode_starts_from_lengths([len(ep) for ep in episodes])
    expected = {(0, 0): 0.75, (0, 1): 0.2, (1, 0): 1.0, (1, 1): 0.0}
    truth = np.array([expected[(int(o[1]), int(a))] for o, a in zip(obs, act)])
    return obs, act, rew, starts, truth


def test_next_rows_link_each_row_to_the_next_of_its_episode():
    np.testing.assert_array_equal(next_rows(np.array([0, 3, 4, 6]), 6), [1, 2, -1, -1, 5, -1])


def test_fitted_q_is_the_behaviours_q_through_the_logged_next_actions():
    obs, act, rew, starts, truth = two_step_log()
    q = fitted_q_values(obs, act, rew, starts, 1.0, n_actions=2, config=SMALL)
    np.testing.assert_allclose(q, truth, atol=0.02)
    # the Monte-Carlo return of the episode whose B step paid 0 is 0; FQE shares B's value
    assert abs(q[6] - 0.75) < 0.02


def test_fitted_q_values_the_next_observation_by_every_row_logged_there():
    """A then B twice (B's next dose: 0 once, 1 once), B alone twice (dose 0): at B dose 0
    pays 1 and dose 1 pays 0, and the log's rows at B took dose 0 three times in four, so
    Q(A, 0) = V(B) = 0.75 (expected targets), where the doses that happened to follow A
    give 0.5 (the logged next rows' Q, SARSA)."""
    a_obs, b_obs = [1.0, 0.0], [0.0, 1.0]
    episodes = [[(a_obs, 0, 0.0), (b_obs, 0, 1.0)], [(a_obs, 0, 0.0), (b_obs, 1, 0.0)],
                [(b_obs, 0, 1.0)], [(b_obs, 0, 1.0)]]
    rows = [step for ep in episodes for step in ep]
    obs = np.array([r[0] for r in rows], np.float32)
    act = np.array([r[1] for r in rows], np.int64)
    rew = np.array([r[2] for r in rows])
    starts = episode_starts_from_lengths([len(ep) for ep in episodes])
    q = fitted_q_values(obs, act, rew, starts, 1.0, n_actions=2, config=SMALL)
    np.testing.assert_allclose(q, [0.75, 1.0, 0.75, 0.0, 1.0, 1.0], atol=0.02)
    sarsa = fitted_q_values(obs, act, rew, starts, 1.0, n_actions=2,
                            config=replace(SMALL, next_value="logged"))
    np.testing.assert_allclose(sarsa, [0.5, 1.0, 0.5, 0.0, 1.0, 1.0], atol=0.02)


def test_expected_and_logged_targets_agree_where_no_observation_repeats():
    rng = np.random.default_rng(1)
    obs = rng.normal(size=(60, 3)).astype(np.float32)
    act = rng.integers(0, 3, 60)
    rew = rng.random(60)
    starts = episode_starts_from_lengths([6] * 10)
    a = fitted_q_values(obs, act, rew, starts, 0.9, n_actions=3, config=SMALL)
    b = fitted_q_values(obs, act, rew, starts, 0.9, n_actions=3,
                        config=replace(SMALL, next_value="logged"))
    np.testing.assert_allclose(a, b, rtol=1e-5, atol=1e-6)   # two code paths: a few ulp apart at most


def test_fitted_q_discounts_the_next_value():
    obs, act, rew, starts, truth = two_step_log()
    q = fitted_q_values(obs, act, rew, starts, 0.5, n_actions=2, config=SMALL)
    np.testing.assert_allclose(q[act + 2 * obs[:, 1].astype(int) == 0], 0.375, atol=0.02)


def test_fitted_q_of_continuous_actions_reads_the_action():
    # one state, the action a in [-1, 1] pays a^2 and ends: Q(o, a) = a^2
    rng = np.random.default_rng(0)
    act = rng.uniform(-1, 1, (400, 1))
    obs = np.zeros((400, 2), np.float32)
    q = fitted_q_values(obs, act, act[:, 0] ** 2, np.arange(401), 0.9,
                        config=FQEConfig(iterations=2, steps=400, hidden=32))
    assert np.abs(q - act[:, 0] ** 2).max() < 0.1


def test_fitted_q_is_reproducible():
    obs, act, rew, starts, _ = two_step_log()
    a = fitted_q_values(obs, act, rew, starts, 1.0, n_actions=2, config=SMALL)
    b = fitted_q_values(obs, act, rew, starts, 1.0, n_actions=2, config=SMALL)
    np.testing.assert_array_equal(a, b)


def test_value_fqe_of_a_corpus_and_its_recorded_definition(tmp_path, monkeypatch):
    import aoc_cli.belief.fqe as fqe
    import aoc_cli.belief.targets as targets

    monkeypatch.setattr(fqe, "FQEConfig", lambda: SMALL)       # the settings run
    monkeypatch.setattr(targets, "FQEConfig", lambda: SMALL)   # the settings recorded
    obs, act, rew, starts, truth = two_step_log()
    n = len(act)
    data = CorpusData(observations=obs, actions=act, rewards=rew.astype(np.float32),
                      terminals=np.isin(np.arange(n), starts[1:] - 1),
                      truncations=np.zeros(n, bool), episode_starts=starts,
                      observation_space=box_space(2), action_space=discrete_space(2))
    corpus = Store(tmp_path).write("two", data)
    np.testing.assert_allclose(value_targets(corpus, "fqe", 1.0), truth, atol=0.02)
    spec = value_spec("fqe", 1.0)
    assert spec["target"] == "fqe" and spec["gamma"] == 1.0 and spec["fqe"]["iterations"] == 6


def test_fqe_needs_rewards_and_a_gamma_in_range(tmp_path):
    obs, act, rew, starts, _ = two_step_log()
    with pytest.raises(AocError, match="gamma"):
        fitted_q_values(obs, act, rew, starts, 1.5, n_actions=2, config=SMALL)
    with pytest.raises(AocError, match="next_value"):
        fitted_q_values(obs, act, rew, starts, 1.0, n_actions=2,
                        config=replace(SMALL, next_value="greedy"))
    n = len(act)
    data = CorpusData(observations=obs, actions=act, rewards=None,
                      terminals=np.zeros(n, bool), truncations=np.zeros(n, bool),
                      episode_starts=starts, observation_space=box_space(2),
                      action_space=discrete_space(2))
    corpus = Store(tmp_path).write("free", data)
    with pytest.raises(AocError, match="no rewards"):
        value_targets(corpus, "fqe", 1.0)
