"""The paper's point: the history identifies the dynamics. Checked on a synthetic corpus where
the value depends on a hidden system, and on pendulum-het (``aoc_cli.envs.collect``)."""

import numpy as np
import pytest

from aoc_cli.belief import (BeliefConfig, episode_rows, load_model, logistic_probe,
                            split_episodes, train_model)
from aoc_cli.belief.train import dynamics_targets
from aoc_cli.envs import collect
from aoc_cli.errors import AocError
from aoc_cli.store import Store

from tests.belief.corpora import hidden_system

FAST = dict(threads=1, hidden=64, patience=5)


def system_probes(corpus, beliefs, config):
    """(probe accuracy on beliefs, on (o, a)) for the validation episodes of the split."""
    train_eps, val_eps = split_episodes(corpus.n_episodes, config.val_fraction, config.seed)
    tr = episode_rows(corpus.episode_starts, train_eps)
    va = episode_rows(corpus.episode_starts, val_eps)
    system = corpus.tag("system")[0]
    oa = np.concatenate([corpus.observations, corpus.actions], axis=1)
    return (logistic_probe(beliefs[tr], system[tr], beliefs[va], system[va]),
            logistic_probe(oa[tr], system[tr], oa[va], system[va]))


def test_beliefs_with_history_identify_a_hidden_system_the_value_depends_on(tmp_path):
    corpus = Store(tmp_path).write("hs", hidden_system())
    cfg = dict(value="v", max_epochs=20, batch_size=50, **FAST)
    config = BeliefConfig(history_length=4, **cfg)
    with_history = train_model(corpus, config, "L4")
    without = train_model(corpus, BeliefConfig(history_length=0, **cfg), "L0")
    assert with_history["val_r2"] > 0.8
    assert with_history["val_r2"] > without["val_r2"] + 0.5
    on_beliefs, on_oa = system_probes(corpus, load_model(corpus, "L4").row_beliefs(corpus),
                                      config)
    assert on_oa < 0.65           # (o, a) says nothing about the system
    assert on_beliefs > 0.9       # the belief does (all but the first row of each episode)


@pytest.fixture(scope="module")
def pendulum(tmp_path_factory):
    data, _summary = collect("pendulum-het", steps=20_000, seed=0)
    return Store(tmp_path_factory.mktemp("store")).write("pendulum", data)


def test_pendulum_het_value_is_better_predicted_with_the_history(pendulum):
    # At this size (collect seed 0, default hidden 128, up to 200 epochs) we measured
    # L = 4 0.80 and L = 0 0.72 (README, "Training the belief model").
    # docs/notes/belief.md has the figures at 100k rows and why the system probe is not asserted
    # in value mode.
    cfg = dict(max_epochs=15, **FAST)
    with_history = train_model(pendulum, BeliefConfig(history_length=4, **cfg), "L4")
    without = train_model(pendulum, BeliefConfig(history_length=0, **cfg), "L0")
    assert with_history["val_r2"] > without["val_r2"] + 0.03
    assert without["val_r2"] > 0.5


def test_dynamics_head_makes_beliefs_encode_a_system_the_value_ignores(tmp_path):
    # The rewards (and so the value) are noise, independent of s: a value-only belief has no
    # reason to encode s. The auxiliary head predicts x' - x = -0.2 x + s a, which needs s
    # (from the history) times a: with it the belief holds s as an interaction with a.
    corpus = Store(tmp_path).write("hs", hidden_system())
    cfg = dict(value="reward", max_epochs=25, batch_size=50, **FAST)
    dyn = train_model(corpus, BeliefConfig(dynamics_weight=1.0, **cfg), "dyn")
    flat = train_model(corpus, BeliefConfig(dynamics_weight=1.0, history_length=0, **cfg),
                       "flat")
    plain = train_model(corpus, BeliefConfig(**cfg), "plain")
    assert dyn["val_dynamics_r2"] > 0.85                # the history identifies s
    assert flat["val_dynamics_r2"] < 0.5                # without it, s a is a coin flip
    assert "val_dynamics_r2" not in plain
    split = split_episodes(corpus.n_episodes, 0.2, 0)
    tr, va = (episode_rows(corpus.episode_starts, e) for e in split)
    system = corpus.tag("system")[0]

    def probe(x):
        return logistic_probe(x[tr], system[tr], x[va], system[va], quadratic=True)

    assert probe(load_model(corpus, "dyn").row_beliefs(corpus)) > 0.85
    assert probe(np.concatenate([corpus.observations, corpus.actions], axis=1)) < 0.65
    # The head is for training only: the saved model's beliefs and value are b and l alone,
    # and the model round-trips with the head's weights.
    model = load_model(corpus, "dyn")
    assert model.net.dynamics is not None and model.net.dynamics.out_features == 1
    # the head's target standardisation is saved: its prediction in original units is o' - o
    delta, valid = dynamics_targets(corpus)
    rows = va[valid[va]]
    pred = model.predicted_change(model.row_beliefs(corpus)[rows])
    r2 = 1 - ((pred - delta[rows]) ** 2).sum() / ((delta[rows] - delta[rows].mean(0)) ** 2).sum()
    assert r2 > 0.85
    with pytest.raises(AocError, match="no dynamics head"):
        load_model(corpus, "plain").predicted_change(np.zeros((1, model.d_b)))


def test_dynamics_weight_must_not_be_negative(store, aoc):
    code, out, err = aoc("train", "nothing", "--dynamics-weight", "-1")
    assert code == 2 and out == ""
    assert err.strip().splitlines() == ["aoc: error: --dynamics-weight must be >= 0, got -1.0"]
    code, out, err = aoc("train", "nothing", "--mode", "imitation", "--dynamics-weight", "1")
    assert code == 2 and out == "" and len(err.strip().splitlines()) == 1
    assert "--dynamics-weight needs --mode value" in err


def test_pendulum_het_dynamics_head_makes_the_system_readable_from_the_beliefs(tmp_path):
    # The probe check. The value alone barely depends on the system (docs/notes/belief.md), so
    # the check is made with the auxiliary dynamics head, which needs the effective torque
    # s * a: the belief then holds s as an interaction with a, read by a quadratic logistic
    # probe (measured with these settings: 0.61 on the beliefs, 0.46 on (o, a)).
    data, _summary = collect("pendulum-het", steps=30_000, seed=0)
    corpus = Store(tmp_path).write("pendulum", data)
    config = BeliefConfig(dynamics_weight=1.0, threads=1, max_epochs=30, patience=6)
    metrics = train_model(corpus, config, "dyn")
    assert metrics["val_dynamics_r2"] > 0.9
    split = split_episodes(corpus.n_episodes, config.val_fraction, config.seed)
    tr, va = (episode_rows(corpus.episode_starts, e) for e in split)
    system = corpus.tag("system")[0]
    beliefs = load_model(corpus, "dyn").row_beliefs(corpus)
    oa = np.concatenate([corpus.observations, corpus.actions], axis=1)
    on_beliefs = logistic_probe(beliefs[tr], system[tr], beliefs[va], system[va], quadratic=True)
    on_oa = logistic_probe(oa[tr], system[tr], oa[va], system[va], quadratic=True)
    assert on_oa < 0.55
    assert on_beliefs > on_oa + 0.08
