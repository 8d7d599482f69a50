"""Fitted Q evaluation (aoc_cli.ope.fqe): the direct
method's value of a deterministic and a stochastic policy against the exact values of a small
MDP, with the next action taken from the policy at the next logged step."""

import numpy as np
import pytest

from aoc_cli.ope.fqe import fit_fqe
from aoc_cli.threads import one_thread
from tests.ope.mdps import SmallMDP, mixed_policies


@pytest.mark.parametrize("which", ["greedy", "soft"])
def test_fqe_start_values_match_the_exact_value(which):
    mdp = SmallMDP.random(seed=1, end=0.35)
    s, a = mdp.P.shape[:2]
    pi_b, greedy, soft, _rng = mixed_policies(mdp, 1)
    pi_e = greedy if which == "greedy" else soft
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


def test_the_behaviour_member_is_the_same_alone_and_beside_the_policies():
    """fqe_policies(behaviour=True): the logged behaviour's fitted Q evaluation (SARSA) trains
    beside the policies without changing theirs, and equals behaviour_fqe alone; its estimate
    is the mean Q_hat of the episodes' first logged steps."""
    from aoc_cli.ope.fqe import behaviour_fqe, fqe_policies

    mdp = SmallMDP.random(seed=3, end=0.3)
    rng = np.random.default_rng(3)
    s_n, a_n = mdp.P.shape[:2]
    pi_b = rng.dirichlet(np.ones(a_n), size=s_n)
    data = mdp.sample(pi_b, 150, seed=4)
    obs = np.eye(s_n)[data["state"]]
    pol = np.eye(a_n)[rng.integers(0, a_n, s_n)][data["state"]]
    args = (obs, data["action"], data["reward"], data["starts"])
    with one_thread():
        plain = fqe_policies(*args, [pol], steps=400, refits=3)
        both = fqe_policies(*args, [pol], steps=400, refits=3, behaviour=True)
        alone = behaviour_fqe(*args, a_n, steps=400)
    assert len(plain) == 1 and len(both) == 2
    assert both[0]["estimate"] == pytest.approx(plain[0]["estimate"], abs=1e-6)
    np.testing.assert_allclose(both[1]["logged"], alone["logged"], atol=1e-5)
    rows = np.arange(len(data["action"]))
    np.testing.assert_allclose(alone["logged"], alone["q"][rows, data["action"]])
    assert alone["estimate"] == pytest.approx(alone["logged"][data["starts"][:-1]].mean())
    assert np.abs(alone["logged"]).max() > 0.1            # it learned something
