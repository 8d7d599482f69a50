"""``aoc evaluate``'s value targets of a held-out log: fqe targets computed once and kept
beside the log with what they were computed from, read back only when all of it matches;
Adam's one-call (foreach) update gives FQE the per-tensor loop's values."""

import json

import numpy as np
import pytest
import torch

from aoc_cli.belief import fqe as fqe_module
from aoc_cli.belief import targets
from aoc_cli.belief.fqe import FQEConfig, fitted_q_values
from aoc_cli.store import CorpusData, Store, discrete_space, episode_starts_from_lengths
from aoc_cli.store import box_space, targets_dir

#: A small FQE (the defaults' 18,000 gradient steps are for real logs).
SMALL = FQEConfig(iterations=4, steps=40, hidden=16, final_iterations=1)


def _log(seed: int = 0, episodes: int = 30) -> CorpusData:
    rng = np.random.default_rng(seed)
    lengths = rng.integers(1, 6, episodes)
    n = int(lengths.sum())
    obs = rng.integers(0, 4, (n, 2)).astype(np.float32)       # observations repeat
    terminals = np.zeros(n, bool)
    terminals[np.cumsum(lengths) - 1] = True
    return CorpusData(observations=obs, actions=rng.integers(0, 3, n),
                      rewards=rng.random(n), terminals=terminals, truncations=np.zeros(n, bool),
                      episode_starts=episode_starts_from_lengths(lengths),
                      observation_space=box_space(2), action_space=discrete_space(3))


@pytest.fixture
def held(tmp_path, monkeypatch):
    """A stored log, FQE small, and the number of times its targets were computed."""
    monkeypatch.setattr(fqe_module, "FQEConfig", lambda: SMALL)
    calls = []
    real = targets.value_targets

    def counted(*args, **kwargs):
        calls.append(args[1:])
        return real(*args, **kwargs)

    monkeypatch.setattr(targets, "value_targets", counted)
    store = Store(tmp_path)
    store.write("held", _log())
    return store.corpus("held"), calls, real


def test_fqe_targets_of_a_held_out_log_are_computed_once_and_kept(held):
    corpus, calls, real = held
    first = targets.held_out_targets(corpus, "fqe", 1.0)
    np.testing.assert_allclose(first, real(corpus, "fqe", 1.0), rtol=1e-12, atol=1e-15)
    kept = sorted(p.name for p in targets_dir(corpus.path).iterdir())
    assert len(kept) == 2 and kept[0].endswith(".json") and kept[1].endswith(".npy")
    record = json.loads((targets_dir(corpus.path) / kept[0]).read_text())
    assert record["corpus"] == corpus.hash and record["gamma"] == 1.0
    assert record["fqe"] == FQEConfig().to_dict()
    again = targets.held_out_targets(corpus, "fqe", 1.0)
    assert len(calls) == 1                      # read back, not computed again
    np.testing.assert_array_equal(again, first)


def test_other_settings_compute_their_own_targets(held):
    corpus, calls, real = held
    one = targets.held_out_targets(corpus, "fqe", 1.0)
    half = targets.held_out_targets(corpus, "fqe", 0.5)
    assert len(calls) == 2
    np.testing.assert_allclose(half, real(corpus, "fqe", 0.5), rtol=1e-12, atol=1e-15)
    assert not np.allclose(one, half)
    assert len(list(targets_dir(corpus.path).glob("*.npy"))) == 2


def test_kept_targets_that_do_not_match_their_hash_are_computed_again(held):
    corpus, calls, _real = held
    first = targets.held_out_targets(corpus, "fqe", 1.0)
    npy = next(targets_dir(corpus.path).glob("*.npy"))
    np.save(npy, first + 1.0)                   # damaged: same shape, other values
    again = targets.held_out_targets(corpus, "fqe", 1.0)
    assert len(calls) == 2
    np.testing.assert_array_equal(again, first)


def test_targets_of_a_rewritten_log_are_not_the_old_logs(held, tmp_path):
    corpus, calls, real = held
    targets.held_out_targets(corpus, "fqe", 1.0)
    Store(tmp_path).write("held", _log(seed=1), overwrite=True)
    new = Store(tmp_path).corpus("held")
    assert new.hash != corpus.hash
    got = targets.held_out_targets(new, "fqe", 1.0)
    assert len(calls) == 2
    np.testing.assert_allclose(got, real(new, "fqe", 1.0), rtol=1e-12, atol=1e-15)


def test_returns_are_computed_each_time_and_not_kept(held):
    corpus, calls, real = held
    got = targets.held_out_targets(corpus, "return", 0.9)
    np.testing.assert_array_equal(got, real(corpus, "return", 0.9))
    assert not targets_dir(corpus.path).exists()


def test_fqe_with_the_one_call_adam_update_has_the_per_tensor_loops_values(monkeypatch):
    data = _log(episodes=60)
    args = (data.observations, data.actions, data.rewards, data.episode_starts, 0.9)
    fast = fitted_q_values(*args, n_actions=3, config=SMALL)
    adam = torch.optim.Adam
    monkeypatch.setattr(torch.optim, "Adam",
                        lambda params, **kw: adam(params, **{**kw, "foreach": False}))
    loop = fitted_q_values(*args, n_actions=3, config=SMALL)
    np.testing.assert_allclose(fast, loop, rtol=1e-6, atol=1e-7)
