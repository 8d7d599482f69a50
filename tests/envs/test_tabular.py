"""The exact evaluator of tabular MDPs against values computed by hand."""

import numpy as np
import pytest

from aoc_cli.envs.tabular import TabularMDP, greedy
from aoc_cli.errors import AocError


def two_rooms() -> TabularMDP:
    """Live states 0 and 1, terminal win W (2) and loss L (3); reward 1 on entering W.

    s0: a0 -> W 0.6, L 0.4;  a1 -> s1.
    s1: a0 -> W 0.9, L 0.1;  a1 -> s0 0.5, L 0.5.
    By hand, the uniform policy: V0 = 0.3 + V1 / 2, V1 = 0.45 + V0 / 4, so V0 = V1 = 0.6;
    the optimal policy: s0 -> a1, s1 -> a0, V* = (0.9, 0.9).
    """
    P = np.zeros((4, 2, 4))
    P[0, 0, [2, 3]] = [0.6, 0.4]
    P[0, 1, 1] = 1.0
    P[1, 0, [2, 3]] = [0.9, 0.1]
    P[1, 1, [0, 3]] = [0.5, 0.5]
    P[2, :, 2] = P[3, :, 3] = 1.0
    r = P[:, :, 2].copy()
    r[2:] = 0.0
    return TabularMDP(P, r, np.array([0.5, 0.5, 0.0, 0.0]),
                      np.array([False, False, True, True]))


def test_uniform_policy_values_and_q_match_the_hand_computation():
    mdp = two_rooms()
    uniform = np.full((4, 2), 0.5)
    np.testing.assert_allclose(mdp.state_values(uniform), [0.6, 0.6, 0.0, 0.0], rtol=1e-12)
    assert mdp.value(uniform) == pytest.approx(0.6, rel=1e-12)
    # Q(0, a0) = 0.6, Q(0, a1) = V1 = 0.6, Q(1, a0) = 0.9, Q(1, a1) = V0 / 2 = 0.3
    np.testing.assert_allclose(mdp.q_values(uniform), [[0.6, 0.6], [0.9, 0.3], [0, 0], [0, 0]],
                               rtol=1e-12, atol=1e-15)


def test_deterministic_policies_and_discounting():
    mdp = two_rooms()
    np.testing.assert_allclose(mdp.state_values(np.array([0, 0, 0, 0])), [0.6, 0.9, 0, 0],
                               rtol=1e-12)
    # s0 -> s1 -> W: 0.9 from s1; from s0 a step later, discounted by gamma
    half = TabularMDP(mdp.P, mdp.r, mdp.d0, mdp.terminal, gamma=0.5)
    np.testing.assert_allclose(half.state_values(np.array([1, 0, 0, 0])), [0.45, 0.9, 0, 0],
                               rtol=1e-12)
    # a deterministic policy and its one-hot stochastic form have the same values
    one_hot = np.array([[0.0, 1.0], [1.0, 0.0], [1.0, 0.0], [1.0, 0.0]])
    assert mdp.value(one_hot) == mdp.value(np.array([1, 0, 1, 1]))


def test_optimal_values_and_policy():
    v, policy = two_rooms().optimal()
    np.testing.assert_allclose(v, [0.9, 0.9, 0.0, 0.0], rtol=1e-12)
    assert policy[:2].tolist() == [1, 0]


def test_greedy_restricted_to_a_support():
    q = np.array([[0.6, 0.9], [0.9, 0.3]])
    assert greedy(q).tolist() == [1, 0]
    support = np.array([[True, False], [False, False]])   # state 1: no support -> all actions
    assert greedy(q, support).tolist() == [0, 0]
    assert greedy(np.array([[0.5, 0.5]])).tolist() == [0]  # ties -> the lowest index


def test_a_policy_that_never_ends_is_refused():
    P = np.zeros((2, 1, 2))
    P[0, 0, 0] = 1.0                      # state 0 loops on itself forever
    P[1, 0, 1] = 1.0
    mdp = TabularMDP(P, np.zeros((2, 1)), np.array([1.0, 0.0]), np.array([False, True]))
    with pytest.raises(AocError, match="never reaches a terminal state"):
        mdp.value(np.array([0, 0]))
    assert TabularMDP(P, np.ones((2, 1)), mdp.d0, mdp.terminal, gamma=0.9).value(
        np.array([0, 0])) == pytest.approx(10.0, rel=1e-12)   # 1 / (1 - 0.9)


def test_bad_policies_and_tables_are_refused():
    mdp = two_rooms()
    with pytest.raises(AocError, match="do not sum to 1"):
        mdp.value(np.array([[0.5, 0.4], [0.5, 0.5], [0, 0], [0, 0]]))
    with pytest.raises(AocError, match="action 2 in state 1"):
        mdp.value(np.array([0, 2, 0, 0]))
    with pytest.raises(AocError, match=r"\(4,\) action indices"):
        mdp.value(np.array([0.0, 1.0, 0.0, 0.0]))
    with pytest.raises(AocError, match="inconsistent shapes"):
        TabularMDP(mdp.P[:, :1], mdp.r, mdp.d0, mdp.terminal)
