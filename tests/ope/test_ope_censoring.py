"""Censoring (aoc_cli.ope.estimators, aoc_cli.ope.fqe): episodes a random clock cuts short,
marked truncated, are censored by PDWIS, WDR and FQE, which then recover a small MDP's exact
value; counted as ended, they are far off."""

import numpy as np
import pytest

from aoc_cli.ope.estimators import Log, bootstrap, pdwis, ratios, wdr
from tests.ope.mdps import SmallMDP, mixed_policies


def _cut(data, rng, hazard=0.15):
    """The log with each episode cut after a geometric number of steps (a clock independent of
    the outcome): (rows kept, starts, truncated (E,))."""
    starts = data["starts"]
    lengths = np.diff(starts)
    cut = rng.geometric(hazard, size=len(lengths))
    kept = np.minimum(lengths, cut)
    rows = np.concatenate([np.arange(s, s + k) for s, k in zip(starts[:-1], kept)])
    return rows, np.concatenate([[0], np.cumsum(kept)]), cut < lengths


def test_pdwis_and_wdr_censor_truncated_episodes_and_recover_the_exact_value():
    mdp = SmallMDP.random(seed=1, end=0.35)
    s, a = mdp.P.shape[:2]
    pi_b, greedy, _soft, rng = mixed_policies(mdp, 1)
    truth, q = mdp.exact(greedy)
    behaviour, _ = mdp.exact(pi_b)
    data = mdp.sample(pi_b, 20000, seed=2)
    rows, starts, truncated = _cut(data, rng)
    assert 0.1 < truncated.mean() < 0.4
    st, ac, r = data["state"][rows], data["action"][rows], data["reward"][rows]
    rho = ratios(greedy[st, ac], data["propensity"][rows])
    v = (greedy * q).sum(1)
    censored = Log(starts, r, truncated=truncated)
    as_ended = Log(starts, r)
    # 20,000 episodes: the tolerance is 3-4 standard errors; counted as ended, 0.1 off
    assert pdwis(censored, rho) == pytest.approx(truth, abs=0.02)
    assert wdr(censored, rho, q[st, ac], v[st]) == pytest.approx(truth, abs=0.02)
    assert pdwis(censored, np.ones(len(r))) == pytest.approx(behaviour, abs=0.02)
    assert pdwis(as_ended, rho) < truth - 0.06
    assert wdr(as_ended, rho, q[st, ac], v[st]) < truth - 0.06
    est = bootstrap(censored, {"pdwis": ("pdwis", rho)}, n_boot=200)["pdwis"]
    assert est.low <= truth <= est.high


def test_a_censored_step_counts_at_its_step_and_then_leaves():
    """By hand: episode 0 survives at its one step (reward 1); episode 1 is cut after its
    first step (reward 0 there, known to go on); episode 2 survives at its second step
    (rewards 0, 1). Step 0: mean reward 1/3, episodes 1 and 2 go on (c_0 = 2/3); step 1:
    episode 2 alone, reward 1. Kaplan-Meier: 1/3 + 2/3 * 1 = 1 (every episode seen to its end
    survived). Counted as ended, episode 1 scores 0: 1/3 + 1/3 * 1 = 2/3."""
    starts = np.array([0, 1, 2, 4])
    rewards = np.array([1.0, 0.0, 0.0, 1.0])
    censored = Log(starts, rewards, truncated=np.array([False, True, False]))
    assert pdwis(censored, np.ones(4)) == pytest.approx(1.0, abs=1e-12)
    assert pdwis(Log(starts, rewards), np.ones(4)) == pytest.approx(2 / 3, abs=1e-12)


@pytest.mark.parametrize("seed", [0, 1])
def test_fqe_bootstraps_a_censored_step_and_recovers_the_exact_value(seed):
    """FQE on a log whose episodes a random clock cuts short (a fifth to a third of them):
    each censored step's target is r + gamma C(s, a), C the value of the next state that the
    continuing transitions predict, and the estimate (the mean start value) is the exact
    value's; the cuts taken as terminal (reward 0, nothing after) are far below it."""
    from aoc_cli.ope.fqe import fit_fqe
    from aoc_cli.threads import one_thread

    mdp = SmallMDP.random(seed=1, end=0.35)
    s, a = mdp.P.shape[:2]
    pi_b, greedy, _soft, rng = mixed_policies(mdp, 1)
    _, q = mdp.exact(greedy)
    data = mdp.sample(pi_b, 3000, seed=2 + seed)
    rows, starts, truncated = _cut(data, np.random.default_rng(seed))
    assert 0.1 < truncated.mean() < 0.4
    st, ac, r = data["state"][rows], data["action"][rows], data["reward"][rows]
    first = starts[:-1]
    exact = float(np.mean((greedy * q).sum(1)[st[first]]))     # these episodes' start states
    args = (np.eye(s)[st], ac, r, starts, greedy[st])

    def estimate(cut):
        with one_thread():
            q_hat = fit_fqe(*args, steps=1500, seed=seed, truncated=cut)
        return float(np.mean((greedy[st[first]] * q_hat[first]).sum(1))), q_hat

    censored, q_hat = estimate(truncated)
    as_ended, _ = estimate(None)
    # measured within 0.008 of the exact value (seeds 0-3), taken as ended 0.085-0.098 below
    assert censored == pytest.approx(exact, abs=0.02)
    assert np.abs(q_hat - q[st]).max() < 0.1
    assert as_ended < exact - 0.05
