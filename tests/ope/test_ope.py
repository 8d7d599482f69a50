"""Offline policy evaluation (aoc_cli.ope.estimators): the per-decision weights and both
estimators by hand on two ragged episodes; PDWIS and WDR against exact policy values of small
MDPs (reward only at the end, episodes of random length); bootstrap coverage; bad input."""

import numpy as np
import pytest

from aoc_cli.errors import AocError
from aoc_cli.ope.estimators import Log, bootstrap, ess, padded, pdwis, ratios, wdr
from tests.ope.mdps import SmallMDP, mixed_policies

# Two episodes by hand: lengths 2 and 3, the reward only at each end.
STARTS = np.array([0, 2, 5])
REWARDS = np.array([0.0, 1.0, 0.0, 0.0, 1.0])
RHO = np.array([2.0, 0.5, 0.5, 2.0, 4.0])
Q = np.array([0.3, 0.6, 0.2, 0.1, 0.7])
V = np.array([0.4, 0.5, 0.3, 0.2, 0.6])


def test_cumulative_weights_carry_forward_after_an_episode_ends():
    W = Log(STARTS, REWARDS).weights(RHO)
    # episode 0: 2, 2 * 0.5 = 1, then absorbed (ratio 1): 1
    # episode 1: 0.5, 0.5 * 2 = 1, 1 * 4 = 4
    assert W.tolist() == [[2.0, 1.0, 1.0], [0.5, 1.0, 4.0]]
    assert padded(STARTS, REWARDS).tolist() == [[0, 1, 0], [0, 0, 1]]


def test_pdwis_matches_a_hand_computation():
    # running weights n_t: t0 2 + 0.5 = 2.5; t1 1 + 1 = 2; t2 (episode 1 only) 4
    # continuation shares: c0 = 2.5 / 2.5 = 1; c1 = 1 / 2 (episode 0 ends at t1); S = 1, 1, 0.5
    # t0: 0;  t1: S 1 * (1 * 1 + 1 * 0) / 2 = 0.5;  t2: S 0.5 * (4 * 1) / 4 = 0.5
    assert pdwis(Log(STARTS, REWARDS), RHO) == pytest.approx(1.0, abs=1e-12)
    assert pdwis(Log(STARTS, REWARDS, gamma=0.5), RHO) == pytest.approx(
        0.0 + 0.5 * 0.5 + 0.25 * 0.5 * 1.0, abs=1e-12)


def test_wdr_matches_a_hand_computation():
    # mean v_0 = (0.4 + 0.3) / 2 = 0.35; delta = r + v_next - q:
    #   episode 0: 0 + 0.5 - 0.3 = 0.2, 1 + 0 - 0.6 = 0.4
    #   episode 1: 0 + 0.2 - 0.2 = 0.0, 0 + 0.6 - 0.1 = 0.5, 1 + 0 - 0.7 = 0.3
    # t0: (2 * 0.2 + 0.5 * 0) / 2.5 = 0.16; t1: (1 * 0.4 + 1 * 0.5) / 2 = 0.45;
    # t2: S 0.5 * (4 * 0.3) / 4 = 0.15
    assert wdr(Log(STARTS, REWARDS), RHO, Q, V) == pytest.approx(
        0.35 + 0.16 + 0.45 + 0.15, abs=1e-12)


def test_on_episodes_of_one_length_they_are_the_textbook_estimators():
    """S_t = 1: PDWIS = sum_t sum_i w_it r_it / sum_i w_it and Thomas & Brunskill's WDR."""
    rng = np.random.default_rng(0)
    e, t, gamma = 7, 4, 0.9
    starts = np.arange(0, e * t + 1, t)
    r, rho = rng.random(e * t), rng.uniform(0.2, 3, e * t)
    q, v = rng.random(e * t), rng.random(e * t)
    W = np.cumprod(rho.reshape(e, t), axis=1)
    Wn = W / W.sum(0)
    Wprev = np.concatenate([np.full((e, 1), 1 / e), Wn[:, :-1]], axis=1)
    disc = gamma ** np.arange(t)
    R, Qm, Vm = r.reshape(e, t), q.reshape(e, t), v.reshape(e, t)
    textbook_pdwis = np.sum(disc * (Wn * R).sum(0))
    textbook_wdr = textbook_pdwis - np.sum(disc * (Wn * Qm - Wprev * Vm).sum(0))
    log = Log(starts, r, gamma)
    assert pdwis(log, rho) == pytest.approx(textbook_pdwis, rel=1e-12)
    assert wdr(log, rho, q, v) == pytest.approx(textbook_wdr, rel=1e-12)


def test_pdwis_is_conditional_on_ending_where_the_log_still_follows_the_policy():
    # episode 0: one step, survives; episode 1 leaves the policy at its second step (rho 0)
    # t0: n = 2, c0 = 1 / 2, mean reward (1 * 1 + 1 * 0) / 2 = 0.5; t1: no running episode
    # follows the policy: the share S1 = 0.5 still running is beyond the log's reach, so the
    # estimate is conditional on the ended share 1 - S1 = 0.5: 0.5 / 0.5
    log = Log(np.array([0, 1, 4]), np.array([1.0, 0.0, 0.0, 1.0]))
    assert pdwis(log, np.array([1.0, 1.0, 0.0, 1.0])) == pytest.approx(1.0, abs=1e-12)


def test_ess_of_the_whole_trajectory_weights():
    # trajectory weights 2 * 0.5 = 1 and 0.5 * 2 * 4 = 4: (1 + 4)^2 / (1 + 16)
    assert ess(Log(STARTS, REWARDS), RHO) == pytest.approx(25 / 17, abs=1e-12)
    assert ess(Log(STARTS, REWARDS), np.ones(5)) == pytest.approx(2.0, abs=1e-12)


def test_the_behaviour_policy_itself_gives_the_mean_return():
    log = Log(STARTS, REWARDS, gamma=0.9)
    ones = np.ones(5)
    assert pdwis(log, ones) == pytest.approx(np.mean([0.9, 0.81]), abs=1e-12)


def _policies(mdp, seed):
    return mixed_policies(mdp, seed)[:3]   # pi_b, greedy (deterministic), soft (stochastic)


def _estimates(mdp, log_dict, pi_e, gamma=1.0):
    st, ac = log_dict["state"], log_dict["action"]
    log = Log(log_dict["starts"], log_dict["reward"], gamma)
    rho = ratios(pi_e[st, ac], log_dict["propensity"])
    _, q = mdp.exact(pi_e, gamma)
    v = (pi_e * q).sum(1)
    return log, rho, q[st, ac], v[st]


@pytest.mark.parametrize("which", ["greedy", "soft"])
@pytest.mark.parametrize("gamma", [1.0, 0.9])
def test_estimators_recover_exact_values_on_ragged_episodes(which, gamma):
    mdp = SmallMDP.random(seed=1, end=0.35)
    pi_b, greedy, soft = _policies(mdp, 1)
    pi_e = greedy if which == "greedy" else soft
    truth, _ = mdp.exact(pi_e, gamma)
    behaviour, _ = mdp.exact(pi_b, gamma)
    assert abs(truth - behaviour) > 0.02        # the estimators must move off the log's mean
    data = mdp.sample(pi_b, 20000, seed=2)
    assert np.diff(data["starts"]).max() >= 8   # ragged: lengths 1 to many
    log, rho, q, v = _estimates(mdp, data, pi_e, gamma)
    est = bootstrap(log, {"pdwis": ("pdwis", rho), "wdr": ("wdr", rho, q, v)}, n_boot=400)
    # statistical tolerances (20,000 episodes: 4 standard errors); the mistake the module
    # docstring names is off by far more
    assert est["pdwis"].estimate == pytest.approx(truth, abs=0.03)
    assert est["wdr"].estimate == pytest.approx(truth, abs=0.03)
    for e in est.values():
        assert e.low <= truth <= e.high
    assert est["pdwis"].estimate == pytest.approx(pdwis(log, rho), abs=1e-12)
    assert est["wdr"].estimate == pytest.approx(wdr(log, rho, q, v), abs=1e-12)


def test_running_normalisation_without_the_continuation_share_would_fail():
    """Normalising each step over the running episodes but dropping S_t sums conditional
    rewards (a hazard, not a value): far off, and pdwis is not."""
    mdp = SmallMDP.random(seed=1, end=0.35)
    pi_b, greedy, _ = _policies(mdp, 1)
    truth, _ = mdp.exact(greedy)
    data = mdp.sample(pi_b, 20000, seed=4)
    log, rho, _, _ = _estimates(mdp, data, greedy)
    W = log.weights(rho) * log.mask
    wrong = np.sum(np.sum(W * log.R, 0) / np.maximum(W.sum(0), 1e-300))
    assert abs(wrong - truth) > 0.1
    assert abs(pdwis(log, rho) - truth) < 0.04


def test_bootstrap_intervals_cover_the_truth_at_about_their_level():
    mdp = SmallMDP.random(seed=2, end=0.35)
    pi_b, greedy, _ = _policies(mdp, 2)
    truth, _ = mdp.exact(greedy)
    covered = {"pdwis": 0, "wdr": 0}
    for seed in range(40):
        data = mdp.sample(pi_b, 1000, seed=100 + seed)
        log, rho, q, v = _estimates(mdp, data, greedy)
        est = bootstrap(log, {"pdwis": ("pdwis", rho), "wdr": ("wdr", rho, q, v)},
                        n_boot=300, seed=seed)
        for k, e in est.items():
            covered[k] += e.low <= truth <= e.high
    # nominal 38 of 40; weighted estimators' percentile intervals run a little short
    assert covered["pdwis"] >= 34 and covered["wdr"] >= 34


def test_mean_estimator_is_the_average_with_an_interval():
    log = Log(STARTS, REWARDS)
    est = bootstrap(log, {"m": ("mean", np.array([0.2, 0.6]))}, n_boot=200)["m"]
    assert est.estimate == pytest.approx(0.4, abs=1e-12)
    assert 0.2 <= est.low <= est.high <= 0.6


def test_zero_propensity_of_a_logged_action_is_refused():
    with pytest.raises(AocError, match="propensity of logged step 1 is 0.0"):
        ratios(np.ones(3), np.array([0.5, 0.0, 0.2]))


def test_a_propensity_above_one_is_refused():
    with pytest.raises(AocError, match=r"propensity of logged step 2 is 1.5: a logged "
                                       r"action's probability must be in \(0, 1\]"):
        ratios(np.ones(3), np.array([0.5, 1.0, 1.5]))


def test_a_policy_that_never_matches_the_log_is_undefined_not_zero():
    log = Log(STARTS, REWARDS)
    assert np.isnan(pdwis(log, np.zeros(5)))
    assert np.isnan(wdr(log, np.zeros(5), Q, V))
    assert ess(log, np.zeros(5)) == 0.0
