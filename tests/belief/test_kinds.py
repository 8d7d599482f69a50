"""What each ``--belief`` kind is trained on: the critic's TD target on a tiny MDP with a known
Q, the reward model's head predicts the reward, the config records the kind, and every kind's
saved head maps the belief to the chosen value."""

import json

import numpy as np
import pytest
import torch

from aoc_cli.belief import BeliefConfig, load_model, train_model
from aoc_cli.belief.critic import td_target, transitions
from aoc_cli.belief.data import episode_rows, split_episodes
from aoc_cli.belief.kinds import fit_head
from aoc_cli.belief.targets import value_targets
from aoc_cli.cli.errors import message
from aoc_cli.errors import BadSetting
from aoc_cli.store import CorpusData, Store, box_space, episode_starts_from_lengths

from tests.belief.corpora import known_value, synthetic_value

FAST = dict(threads=1, max_epochs=12, patience=5, batch_size=250, hidden=64)
GAMMA = 0.5


def bandit_chain(episodes: int = 20, length: int = 100, seed: int = 0) -> CorpusData:
    """o ~ U(-1, 1) i.i.d. at every step whatever the action, a ~ U(-1, 1) (the behaviour),
    r = 1 - (a - o)^2; episodes are cut off (truncated), never terminal. The optimal policy is
    a = o, so V* = 1 / (1 - gamma) and Q*(o, a) = 1 - (a - o)^2 + gamma / (1 - gamma)."""
    rng = np.random.default_rng(seed)
    n = episodes * length
    obs = rng.uniform(-1, 1, (n, 1)).astype(np.float32)
    act = rng.uniform(-1, 1, (n, 1)).astype(np.float32)
    trunc = np.zeros(n, bool)
    starts = episode_starts_from_lengths(np.full(episodes, length))
    trunc[starts[1:] - 1] = True
    return CorpusData(observations=obs, actions=act, rewards=1.0 - (act[:, 0] - obs[:, 0]) ** 2,
                      terminals=np.zeros(n, bool), truncations=trunc, episode_starts=starts,
                      observation_space=box_space(1, -1, 1), action_space=box_space(1, -1, 1))


def test_td_target_bootstraps_the_smaller_twin_except_at_a_terminal():
    y = td_target(torch.tensor([1.0, 1.0]), torch.tensor([0.0, 1.0]),
                  torch.tensor([4.0, 4.0]), torch.tensor([2.0, 8.0]), 0.5)
    np.testing.assert_allclose(y.numpy(), [2.0, 1.0])


def test_transitions_know_which_rows_have_a_td_target(tmp_path):
    data = synthetic_value(episodes=3, length=4)  # terminal at the end of every episode
    data.terminals[7] = False                     # the second episode is cut off instead
    data.truncations[7] = True
    corpus = Store(tmp_path).write("t", data)
    nxt, done, usable = transitions(corpus)
    np.testing.assert_array_equal(nxt, [1, 2, 3, 3, 5, 6, 7, 7, 9, 10, 11, 11])
    np.testing.assert_array_equal(done, [0, 0, 0, 1, 0, 0, 0, 0, 0, 0, 0, 1])
    assert usable.tolist() == [True] * 7 + [False] + [True] * 4


def test_critic_learns_the_known_q_of_a_tiny_mdp(tmp_path):
    corpus = Store(tmp_path).write("chain", bandit_chain())
    config = BeliefConfig(belief="critic", gamma=GAMMA, history_length=0, hidden=32,
                          belief_dim=8, critic_steps=2000, batch_size=256, threads=1)
    metrics = train_model(corpus, config, "q")
    meta = json.loads((corpus.models_dir / "q" / "config.json").read_text())
    assert meta["config"]["belief"] == "critic" and metrics["belief"] == "critic"
    # Q from the belief through the critic's own (saved) linear head, in reward units
    model = load_model(corpus, "q")
    q_head = meta["critic"]["q_head"]
    o = np.repeat(np.linspace(-0.8, 0.8, 9), 3)[:, None]
    a = np.clip(o + np.tile([0.0, -1.0, 1.0], 9)[:, None], -1, 1)
    b = model.beliefs(o, a).astype(np.float64)
    q = (b @ np.asarray(q_head["weight"]) + q_head["bias"]) * q_head["reward_scale"]
    q_star = 1.0 - (a[:, 0] - o[:, 0]) ** 2 + GAMMA / (1 - GAMMA)
    # the reward's part: Q*(o, o) - Q*(o, a) = (a - o)^2, exactly the TD target's r
    np.testing.assert_allclose(q[0::3] - q[1::3], q_star[0::3] - q_star[1::3], atol=0.2)
    np.testing.assert_allclose(q[0::3] - q[2::3], q_star[0::3] - q_star[2::3], atol=0.2)
    # the bootstrap: Q at the best action is well above the one-step reward 1, on its way to
    # Q* = 2 (the target networks' lag and TD3's smoothing noise keep it a little below)
    assert 1.4 < q[0::3].mean() < 2.1, np.c_[q, q_star]
    # the controller's head maps the same beliefs to the chosen value (return-to-go here)
    assert metrics["val_r2"] > 0.5
    np.testing.assert_array_equal(model.values, value_targets(corpus, "return", GAMMA))


def test_reward_belief_predicts_the_reward_and_its_head_the_value(tmp_path):
    data = synthetic_value(episodes=40, length=50)
    data.rewards = known_value(data.observations, data.actions)  # r is a known f(o, a)
    corpus = Store(tmp_path).write("r", data)
    metrics = train_model(corpus, BeliefConfig(belief="reward", **FAST), "rb")
    assert metrics["belief"] == "reward" and metrics["val_reward_r2"] > 0.9
    model = load_model(corpus, "rb")
    assert model.config.belief == "reward"
    rows = np.arange(0, corpus.n_rows, 5)
    hist = corpus.history(rows, 4)
    b = model.beliefs(corpus.observations[rows], corpus.actions[rows], hist).astype(np.float64)
    # the head was refitted to the return-to-go: predict() is that head, in original units
    weight, bias = model.head_weights
    pred = model.predict(corpus.observations[rows], corpus.actions[rows], hist)
    np.testing.assert_allclose(b @ weight[0] + bias[0], pred, rtol=1e-4, atol=1e-4)
    ret = value_targets(corpus, "return", 0.99)
    np.testing.assert_array_equal(model.values, ret)
    # ... and is the least-squares fit of the return on the training rows' frozen beliefs
    train_eps, _ = split_episodes(corpus.n_episodes, 0.2, 0)
    train = episode_rows(corpus.episode_starts, train_eps)
    w, c = fit_head(model.row_beliefs(corpus)[train], ret[train])
    np.testing.assert_allclose(w, weight[0], rtol=1e-3, atol=1e-3 * np.abs(w).max())
    assert abs(c - bias[0]) < 1e-3 * max(1.0, abs(c))


def test_fit_head_recovers_a_linear_map():
    rng = np.random.default_rng(0)
    b = rng.standard_normal((200, 5))
    w, c = fit_head(b, b @ np.arange(5.0) - 3.0)
    np.testing.assert_allclose(w, np.arange(5.0), atol=1e-9)
    assert abs(c + 3.0) < 1e-9


def test_the_config_names_the_belief_and_dynamics_is_the_weighted_head():
    assert BeliefConfig().belief == "value"
    assert BeliefConfig(dynamics_weight=1.0).belief == "dynamics"   # a model saved before
    assert BeliefConfig(belief="dynamics").dynamics_weight == 1.0
    assert BeliefConfig(belief="dynamics", dynamics_weight=0.5).dynamics_weight == 0.5
    for bad, says in ((dict(belief="q"), "unknown --belief"),
                      (dict(belief="critic", dynamics_weight=1.0), "--dynamics-weight belongs"),
                      (dict(belief="reward", mode="imitation"), "needs --mode value"),
                      (dict(belief="critic", critic_steps=0), "--critic-steps"),
                      (dict(belief="critic", critic_bc_weight=-1), "--critic-bc-weight")):
        with pytest.raises(BadSetting) as err:
            BeliefConfig(**bad)
        assert says in message(err.value)              # the command line's flags
        assert "--" not in str(err.value)              # the library's parameters


def test_critic_steps_scale_with_the_rows_and_are_bounded_by_epochs():
    from aoc_cli.belief.config import CRITIC_STEPS, CRITIC_STEPS_MIN

    cfg = BeliefConfig(belief="critic")
    assert cfg.critic_steps_for(100_000, 80_000)[0] == CRITIC_STEPS == 10_000
    assert cfg.critic_steps_for(300_000, 240_000)[0] == 10_000
    assert cfg.critic_steps_for(50_000, 40_000)[0] == 5_000
    assert cfg.critic_steps_for(4_000, 3_200)[0] == CRITIC_STEPS_MIN == 500
    # --epochs 2: two passes over 3,200 training rows in batches of 500 = 2 x 7 steps
    steps, rule = BeliefConfig(belief="critic", max_epochs=2).critic_steps_for(4_000, 3_200)
    assert steps == 14 and "2 epochs" in rule
    assert BeliefConfig(belief="critic", critic_steps=20,
                        max_epochs=2).critic_steps_for(4_000, 3_200) == (20, "--critic-steps")
