"""The behaviour estimated from a log without propensities (aoc_cli.ope.propensity) against
the true ones: an icu-sepsis log collected with the package's clinician policy, whose
``propensity`` column holds the truth."""

import numpy as np
import pytest

from aoc_cli.envs.icu_sepsis import collect_data, tables
from aoc_cli.ope import estimators as ope
from aoc_cli.ope.propensity import calibration, features, fit_propensities


def test_estimated_propensities_are_close_to_the_true_ones_on_icu_sepsis():
    data, _ = collect_data(episodes=600, seed=1000)
    truth = data.columns["propensity"]
    actions = np.asarray(data.actions, np.int64)
    fit = fit_propensities(data.observations, actions, data.episode_starts, 25, seed=0)
    p = fit["probs"][np.arange(len(actions)), actions]
    true_loss = float(-np.mean(np.log(truth)))
    # held out, the model's log-loss is within 0.15 nats of the truth's and far below the
    # action frequencies'; its (step, action) probabilities are calibrated to 0.01
    assert fit["log_loss"] < true_loss + 0.15
    assert fit["log_loss"] < fit["log_loss_frequencies"] - 0.5
    assert fit["ece"] < 0.01
    assert np.median(np.abs(np.log(p / truth))) < 0.35
    # the clinicians' modal action in each state (a deterministic policy): its first-step
    # weights average about 1, as with the true propensities, and PDWIS is close to PDWIS
    # with the true propensities
    modal = tables().behaviour("clinicians").argmax(1)[data.columns["state"].astype(int)]
    follows = (modal == actions).astype(float)
    log = ope.Log(data.episode_starts, data.rewards)
    estimated, true = ope.ratios(follows, p), ope.ratios(follows, truth)
    assert abs(ope.diagnostics(log, estimated)["first_step_weight"] - 1.0) < 0.1
    assert abs(ope.pdwis(log, estimated) - ope.pdwis(log, true)) < 0.05


def test_history_features_hold_the_previous_steps_within_an_episode():
    obs = np.arange(5.0)[:, None]
    x = features(obs, np.array([1, 0, 1, 1, 0]), np.array([0, 3, 5]), 2, history_length=1)
    # obs, previous obs, previous action one-hot; zeros at each episode's first step
    assert x.tolist() == [[0, 0, 0, 0], [1, 0, 0, 1], [2, 1, 1, 0], [3, 0, 0, 0],
                          [4, 3, 0, 1]]


def test_calibration_of_perfect_probabilities_is_zero_error():
    probs = np.array([[1.0, 0.0], [0.0, 1.0]])
    assert calibration(probs, np.array([0, 1]))["ece"] == 0.0
    assert calibration(np.array([[0.9, 0.1], [0.9, 0.1]]), np.array([1, 1]))["ece"] == \
        pytest.approx(0.9, abs=1e-12)
