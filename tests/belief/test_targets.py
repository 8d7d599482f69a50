import numpy as np
import pytest

from aoc_cli.belief import targets
from aoc_cli.belief.targets import discounted_return_to_go, mean_remaining_reward, value_targets
from aoc_cli.errors import AocError
from aoc_cli.store import Store, episode_starts_from_lengths

from tests.belief.corpora import synthetic_value


def naive_returns(rewards, starts, gamma):
    out = np.zeros(len(rewards))
    for s, e in zip(starts[:-1], starts[1:]):
        g = 0.0
        for t in range(e - 1, s - 1, -1):
            g = rewards[t] + gamma * g
            out[t] = g
    return out


@pytest.mark.parametrize("group_cells", [1 << 22, 7])
def test_discounted_return_matches_a_loop_per_episode(monkeypatch, group_cells):
    # A tiny cell budget forces many groups of episodes of different lengths.
    monkeypatch.setattr(targets, "_GROUP_CELLS", group_cells)
    rng = np.random.default_rng(0)
    lengths = rng.integers(1, 30, 40)
    starts = episode_starts_from_lengths(lengths)
    rewards = rng.standard_normal(starts[-1])
    for gamma in (0.0, 0.9, 1.0):
        np.testing.assert_allclose(discounted_return_to_go(rewards, starts, gamma),
                                   naive_returns(rewards, starts, gamma), rtol=1e-12, atol=1e-12)


def test_truncated_episode_end_is_the_sum_of_remaining_logged_rewards():
    starts = np.array([0, 3, 5])
    rewards = np.array([1.0, 1.0, 1.0, 2.0, 4.0])
    v = discounted_return_to_go(rewards, starts, 0.5)
    # no bootstrapping past the logged end: the last row of each episode is its own reward
    np.testing.assert_allclose(v, [1.75, 1.5, 1.0, 4.0, 4.0])


def test_mean_return_is_the_mean_of_the_remaining_rewards():
    starts = np.array([0, 3, 5])
    rewards = np.array([3.0, 0.0, 6.0, 2.0, 4.0])
    np.testing.assert_allclose(mean_remaining_reward(rewards, starts), [3.0, 3.0, 6.0, 3.0, 4.0])


def test_value_targets_by_name(tmp_path):
    data = synthetic_value(episodes=4, length=5)
    corpus = Store(tmp_path).write("c", data)
    np.testing.assert_allclose(value_targets(corpus, "reward", 0.9), data.rewards)
    np.testing.assert_allclose(value_targets(corpus, "v", 0.9), data.columns["v"])
    np.testing.assert_allclose(value_targets(corpus, "return", 0.9),
                               naive_returns(data.rewards, data.episode_starts, 0.9))


def test_value_targets_refuse_bad_requests(tmp_path):
    store = Store(tmp_path)
    corpus = store.write("c", synthetic_value(episodes=4, length=5))
    with pytest.raises(AocError, match="unknown value 'nope'.*columns: broken, v"):
        value_targets(corpus, "nope", 0.9)
    with pytest.raises(AocError, match="not finite.*first row 7"):
        value_targets(corpus, "broken", 0.9)
    free = store.write("free", synthetic_value(episodes=4, length=5, rewards=False))
    with pytest.raises(AocError, match="has no rewards.*mode='imitation'"):
        value_targets(free, "return", 0.9)
    # a numeric column is still a valid target without rewards
    assert value_targets(free, "v", 0.9).shape == (20,)
