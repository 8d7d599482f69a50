"""Fitted Q evaluation through d3rlpy's DiscreteFQE (aoc_cli.control.ope_fqe): the direct
method's value of a deterministic and a stochastic policy against the exact values of a small
MDP, with the next action taken from the policy at the next logged step."""

import numpy as np
import pytest

from aoc_cli.control.ope_fqe import fit_fqe
from aoc_cli.threads import one_thread

from tests.control.mdps import SmallMDP

pytest.importorskip("d3rlpy", reason="the bench extra (d3rlpy) is not installed")


@pytest.mark.parametrize("which", ["greedy", "soft"])
def test_fqe_start_values_match_the_exact_value(which):
    mdp = SmallMDP.random(seed=1, end=0.35)
    rng = np.random.default_rng(1)
    s, a = mdp.P.shape[:2]
    greedy = np.eye(a)[rng.integers(0, a, size=s)]
    pi_b = 0.5 * greedy + 0.5 * rng.dirichlet(np.full(a, 2.0), size=s)
    pi_e = greedy if which == "greedy" else 0.6 * greedy + 0.4 / a
    truth, q_exact = mdp.exact(pi_e)
    data = mdp.sample(pi_b, 3000, seed=2)
    obs = np.eye(s)[data["state"]]                       # one-hot states
    with one_thread():
        q = fit_fqe(obs, data["action"], data["reward"], data["starts"], pi_e[data["state"]],
                    steps=1500, seed=0)
    first = data["starts"][:-1]
    dm = np.mean((pi_e[data["state"][first]] * q[first]).sum(1))
    # the start values of 3,000 episodes: the exact start-state mean, not the log's returns
    exact_dm = np.mean((pi_e * q_exact).sum(1)[data["state"][first]])
    assert dm == pytest.approx(exact_dm, abs=0.03)
    assert abs(exact_dm - truth) < 0.03
    assert np.abs(q - q_exact[data["state"]]).max() < 0.1
