"""The direct method's interval by a bootstrap of refits (aoc_cli.ope.fqe.bootstrap_fqe):
on a small MDP with one-hot states, where a converged fitted Q evaluation is the tabular
certainty-equivalence estimate, the refits' spread matches that estimate's spread over
resampled logs (computed exactly here by linear solves), and the interval covers the exact
value."""

import numpy as np
import pytest

from aoc_cli.ope.fqe import bootstrap_fqe, refit_steps
from aoc_cli.threads import one_thread
from tests.ope.mdps import SmallMDP, mixed_policies


def tabular_estimate(mdp: SmallMDP, data: dict, pi: np.ndarray, weights: np.ndarray) -> float:
    """The fitted-Q fixed point with one-hot states (a count model of the log, each episode
    counted ``weights[i]`` times), its mean start value over the weighted episodes."""
    s_n, a_n = mdp.P.shape[:2]
    starts = data["starts"]
    w = np.repeat(weights, np.diff(starts)).astype(np.float64)          # (N,) per row
    last = np.zeros(len(w), bool)
    last[starts[1:] - 1] = True
    s, a, r = data["state"], data["action"], data["reward"]
    n = np.zeros((s_n, a_n))
    np.add.at(n, (s, a), w)
    R = np.zeros((s_n, a_n))
    np.add.at(R, (s, a), w * r)
    P = np.zeros((s_n, a_n, s_n))
    nxt = np.append(s[1:], 0)
    keep = ~last
    np.add.at(P, (s[keep], a[keep], nxt[keep]), w[keep])
    seen = n > 0
    R[seen] /= n[seen]
    P[seen] /= n[seen][:, None]
    # Q = R + P V, V = sum_a pi Q  =>  V = (I - P_pi)^-1 r_pi
    p_pi = np.einsum("sa,sat->st", pi, P)
    v = np.linalg.solve(np.eye(s_n) - p_pi, (pi * R).sum(1))
    q = R + P @ v
    first = s[starts[:-1]]
    return float(weights @ (pi * q).sum(1)[first] / weights.sum())


def test_refits_spread_like_the_fitted_estimate_over_resampled_logs_and_cover_the_truth():
    mdp = SmallMDP.random(seed=1, end=0.35)
    s, a = mdp.P.shape[:2]
    pi_b, greedy, soft, _rng = mixed_policies(mdp, 1)
    pi_e = soft
    truth, _q = mdp.exact(pi_e)
    data = mdp.sample(pi_b, 600, seed=2)
    e = len(data["starts"]) - 1
    # the exact bootstrap distribution of the converged estimate (200 resamples)
    boot = np.random.default_rng(5)
    ref = np.array([tabular_estimate(mdp, data, pi_e, boot.multinomial(e, np.full(e, 1 / e)))
                    for _ in range(200)])
    with one_thread():
        out = bootstrap_fqe(np.eye(s)[data["state"]], data["action"], data["reward"],
                            data["starts"], pi_e[data["state"]], steps=1500, refits=12, seed=0)
    assert out["refit_steps"] == refit_steps(1500) and len(out["replicates"]) == 12
    sd = np.std(out["replicates"], ddof=1)
    assert 0.5 * ref.std() < sd < 2.5 * ref.std()
    assert out["low"] < truth < out["high"]
    converged = tabular_estimate(mdp, data, pi_e, np.ones(e))
    # the estimate: the refits' mean (bagged), the interval centred on it; one fit's beside it
    assert out["estimate"] == pytest.approx(converged, abs=0.03)
    assert out["fit_estimate"] == pytest.approx(converged, abs=0.03)
    assert out["estimate"] != out["fit_estimate"]
    assert (out["low"] + out["high"]) / 2 == pytest.approx(out["estimate"], abs=1e-12)
    # +- Student's t (11 degrees of freedom: 2.201) times the replicates' sd
    assert (out["high"] - out["low"]) / 2 == pytest.approx(2.2009851600916384 * sd, rel=1e-9)
