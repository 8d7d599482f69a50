"""The black-box baselines of the bench extra: d3rlpy's TD3+BC / CQL and MPPI over a learned
dynamics model (tiny training budgets: these check the wiring and what was learned, not the
returns)."""

from __future__ import annotations

import numpy as np
import pytest

from aoc_cli.baselines import make_baseline
from tests.baselines.conftest import replay_history


def test_the_d3rlpy_dataset_keeps_the_corpus_episodes_and_context(pendulum):
    from aoc_cli.baselines.features import RawFeatures
    from aoc_cli.baselines.offline_rl import corpus_dataset

    _root, corpus = pendulum
    f = RawFeatures.fit(corpus, 4, with_action=False)
    ds = corpus_dataset(corpus, f)
    assert ds.size() == corpus.n_episodes
    assert sum(len(ep.rewards) for ep in ds.episodes) == corpus.n_rows
    ep = ds.episodes[1]
    start = int(corpus.episode_starts[1])
    np.testing.assert_allclose(ep.observations[3], f.corpus_features(corpus)[start + 3])
    np.testing.assert_allclose(ep.rewards[:, 0], corpus.rewards[start:start + len(ep.rewards)],
                               rtol=1e-6)


@pytest.mark.parametrize("algo", ["td3bc", "cql", "bcq"])
def test_offline_rl_agents_train_and_act_inside_the_box(session, algo):
    from aoc_cli.baselines.offline_rl import OfflineRLConfig

    s, env = session
    policy = make_baseline(algo, s, env, config=OfflineRLConfig(steps=60, batch_size=64,
                                                                threads=1))
    hist = replay_history(s.corpus, 90, s.model.history_length)
    actions = np.array([policy.decide(s.corpus.observations[r], hist) for r in (90, 91, 92)])
    assert actions.shape == (3, 1) and np.all(np.abs(actions) <= 2)
    # same inputs, same action (a deterministic policy)
    np.testing.assert_array_equal(policy.decide(s.corpus.observations[90], hist), actions[0])


def test_the_mpc_dynamics_model_beats_no_change_and_plans_inside_the_box(session):
    import torch

    from aoc_cli.baselines.mpc import MPCConfig, _transitions

    s, env = session
    policy = make_baseline("mpc", s, env, config=MPCConfig(epochs=8, samples=30, horizon=5,
                                                           threads=1))
    corpus = s.corpus
    rows = _transitions(corpus)
    f = policy.features
    x = torch.as_tensor(f.corpus_features(corpus)[rows])
    with torch.no_grad():
        pred = policy.net(x).numpy()
    obs = np.asarray(corpus.observations, np.float64)
    true = (obs[rows + 1] - obs[rows]) / f.obs_std
    assert np.mean((pred[:, :3] - true) ** 2) < 0.5 * np.mean(true ** 2)
    rew = (corpus.rewards[rows] - f.rew_mean) / f.rew_std
    assert np.mean((pred[:, 3] - rew) ** 2) < 0.5 * np.mean(rew ** 2)
    policy.reset()
    hist = replay_history(corpus, 10, s.model.history_length)
    a = policy.decide(corpus.observations[10], hist)
    assert a.shape == (1,) and -2 <= a[0] <= 2
