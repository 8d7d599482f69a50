"""WDR's Q cross-fitted (aoc_cli.ope.fqe.fqe_policies, ``cross``): each policy is also fitted
on each of two folds of the episodes, and each fold's rows get the Q fitted on the other; on a
small MDP with one-hot states each fold's fit converges to the tabular fixed point of the other
fold's episodes, and WDR with the cross-fitted Q is WDR with the exact Q on the same log (the
rest is the log's own sampling error, ~0.03 at 2,000 episodes), near the exact value."""

import numpy as np
import pytest

from aoc_cli.ope.estimators import Log, ratios, wdr
from aoc_cli.ope.estimators import ess as estimated_ess
from aoc_cli.ope.fqe import fqe_policies
from aoc_cli.threads import one_thread
from tests.ope.mdps import SmallMDP, mixed_policies


def tabular_q(data: dict, pi: np.ndarray, episodes: np.ndarray, shape) -> np.ndarray:
    """(S, A) the fitted-Q fixed point with one-hot states of the log's ``episodes`` (E,)
    bool: a count model of their transitions, solved exactly."""
    s_n, a_n = shape
    starts = data["starts"]
    w = np.repeat(episodes, np.diff(starts)).astype(np.float64)
    last = np.zeros(len(w), bool)
    last[starts[1:] - 1] = True
    s, a, r = data["state"], data["action"], data["reward"]
    n, R, P = np.zeros((s_n, a_n)), np.zeros((s_n, a_n)), np.zeros((s_n, a_n, s_n))
    np.add.at(n, (s, a), w)
    np.add.at(R, (s, a), w * r)
    keep = ~last
    np.add.at(P, (s[keep], a[keep], np.append(s[1:], 0)[keep]), w[keep])
    seen = n > 0
    R[seen] /= n[seen]
    P[seen] /= n[seen][:, None]
    v = np.linalg.solve(np.eye(s_n) - np.einsum("sa,sat->st", pi, P), (pi * R).sum(1))
    return R + P @ v


def test_wdr_with_a_cross_fitted_q_recovers_the_exact_value():
    mdp = SmallMDP.random(seed=1, end=0.35)
    s, a = mdp.P.shape[:2]
    pi_b, greedy, _soft, _rng = mixed_policies(mdp, 1)
    truth, q_exact = mdp.exact(greedy)
    data = mdp.sample(pi_b, 2000, seed=2)
    st, ac = data["state"], data["action"]
    args = (np.eye(s)[st], ac, data["reward"], data["starts"], [greedy[st]])
    with one_thread():
        rec = fqe_policies(*args, steps=1500, refits=0, cross=True)[0]
        plain = fqe_policies(*args, steps=1500, refits=0)[0]
    folds = rec["folds"]
    assert abs(folds.mean() - 0.5) < 0.01 and "q_cross" not in plain
    # the policy's own fit does not change with the fold members beside it
    np.testing.assert_allclose(rec["q"], plain["q"], rtol=0, atol=1e-6)
    row_fold = np.repeat(folds, np.diff(data["starts"]))
    for f in (0, 1):
        other = tabular_q(data, greedy, folds != f, (s, a))
        mine = row_fold == f
        assert np.abs(rec["q_cross"][mine] - other[st[mine]]).max() < 0.06
    assert np.abs(rec["q_cross"] - rec["q"]).max() > 0.005     # other fits than the full one
    log = Log(data["starts"], data["reward"])
    rho = ratios(greedy[st, ac], data["propensity"])
    by = lambda q: wdr(log, rho, q[np.arange(len(ac)), ac], (greedy[st] * q).sum(1))
    got, oracle = by(rec["q_cross"]), by(q_exact[st])
    # measured 0.0006-0.002 from the exact Q's WDR on three logs (0.45-0.52: the logs' own
    # sampling error about the exact 0.488)
    assert got == pytest.approx(oracle, abs=0.006)
    assert got == pytest.approx(truth, abs=0.06)


def test_only_a_policy_whose_wdr_the_rule_can_show_gets_fold_fits():
    """fqe_values with the propensities: fold fits for a policy whose ESS meets the rule's 500
    (the behaviour itself here), none for one it withholds at any Q (a far greedy policy)."""
    from aoc_cli.ope.evaluate_block import OPESettings
    from aoc_cli.ope.support import MIN_ESS
    from aoc_cli.ope.value import fqe_values

    mdp = SmallMDP.random(seed=2, end=0.35)
    rng = np.random.default_rng(2)
    s, a = mdp.P.shape[:2]
    pi_b = rng.dirichlet(np.full(a, 2.0), size=s)
    greedy = np.eye(a)[rng.integers(0, a, size=s)]
    data = mdp.sample(pi_b, 600, seed=3)
    st, ac = data["state"], data["action"]
    log = Log(data["starts"], data["reward"])
    policies = [pi_b[st], greedy[st]]
    ess = [float(estimated_ess(log, ratios(p[np.arange(len(ac)), ac], data["propensity"])))
           for p in policies]
    assert ess[0] >= MIN_ESS > ess[1]
    settings = OPESettings(estimators=("wdr",), fqe_steps=300)
    with one_thread():
        recs = fqe_values(log, np.eye(s)[st], ac, policies, settings,
                          propensity=data["propensity"])
        every = fqe_values(log, np.eye(s)[st], ac, policies, settings)
    assert "q_cross" in recs[0] and "q_cross" not in recs[1]
    assert all("q_cross" in r for r in every)          # without propensities: every policy
