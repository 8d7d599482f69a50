"""The risky-decision signal: supporting rows that disagree (one rule for the controller's
per-decision warnings and for ``aoc evaluate``'s batched share)."""

import numpy as np

from aoc_cli.control.config import ControllerConfig
from aoc_cli.control.controller import support_disagreement

CFG = ControllerConfig(min_weight=0.05, action_spread=0.5, value_spread=1.0)


def test_discrete_actions_disagree_only_among_rows_that_carry_weight():
    actions = np.array([0, 0, 1, 1])
    rows = np.array([[0, 1, -1], [0, 2, -1], [0, 2, -1], [3, -1, -1]])
    weights = np.array([[0.5, 0.5, 0], [0.6, 0.4, 0], [0.99, 0.01, 0], [1.0, 0, 0]])
    acts, vals = support_disagreement(rows, weights, actions, None, CFG, discrete=True,
                                      span=None, value_std=1.0)
    # same action; two actions; the other action below min_weight; a single row
    assert acts.tolist() == [False, True, False, False]
    assert not vals.any()


def test_continuous_spread_and_value_range_against_their_thresholds():
    actions = np.array([[0.0, 0.0], [0.9, 0.1], [1.1, 0.0], [0.0, 0.0]])
    values = np.array([0.0, 0.5, 3.0, 0.0])
    span = np.array([2.0, 2.0])  # spread 0.9 / 2 = 0.45 <= 0.5; 1.1 / 2 = 0.55 > 0.5
    rows = np.array([[0, 1], [0, 2], [0, 3]])
    weights = np.full((3, 2), 0.5)
    acts, vals = support_disagreement(rows, weights, actions, values, CFG, discrete=False,
                                      span=span, value_std=2.0)
    assert acts.tolist() == [False, True, False]
    assert vals.tolist() == [False, True, False]  # range 0.5, 3.0, 0 against 1.0 x std 2.0
    _, none = support_disagreement(rows, weights, actions, values, CFG, discrete=False,
                                   span=span, value_std=0.0)
    assert not none.any()
