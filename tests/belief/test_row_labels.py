"""ABC's scores from the named rows (aoc_cli/belief/row_labels.py): each row's label is its
logged action smoothed by lambda towards the belief's probabilities at that row, and an
action's score is the subset's weighted sum of the labels."""

from __future__ import annotations

import numpy as np

from aoc_cli.belief.row_labels import (ROW_SMOOTHING, default_row_smoothing, row_labels,
                                       subset_scores)
from aoc_cli.training.tuning import abc_scores

ROWS = np.array([[3, 0, -1], [1, 2, 4]])
WEIGHTS = np.array([[0.7, 0.3, 0.0], [0.5, 0.25, 0.25]])
ACTIONS = np.array([0, 1, 2, 1, 0])
BELIEFS = np.array([[0.0, 1.0], [2.0, -1.0], [0.5, 0.5], [-1.0, 0.0], [1.0, 1.0]])
HEAD = (np.array([[1.0, 0.0], [0.0, 1.0], [-1.0, -1.0]]), np.array([0.0, 0.5, -0.5]))


def _softmax_by_hand(b):
    z = [b[0], b[1] + 0.5, -b[0] - b[1] - 0.5]
    e = np.exp(np.array(z) - max(z))
    return e / e.sum()


def test_without_smoothing_an_actions_score_is_its_weight_in_the_subset():
    s = subset_scores(ROWS, WEIGHTS, ACTIONS, 3)
    assert np.allclose(s, [[0.3, 0.7, 0.0], [0.25, 0.5, 0.25]], rtol=0, atol=1e-15)
    assert np.array_equal(abc_scores(ROWS, WEIGHTS, ACTIONS, 3), s)  # the paper's score


def test_a_rows_label_mixes_its_logged_action_with_the_beliefs_probabilities_there():
    lab = row_labels(ACTIONS[[3, 0]], BELIEFS[[3, 0]], HEAD, 3, 0.75)
    want = [0.25 * np.eye(3)[ACTIONS[r]] + 0.75 * _softmax_by_hand(BELIEFS[r]) for r in (3, 0)]
    assert np.allclose(lab, want, rtol=0, atol=1e-12)
    assert np.allclose(lab.sum(1), 1.0, rtol=0, atol=1e-12)  # a label is a distribution


def test_the_score_is_the_sum_over_the_named_rows_of_weight_times_label():
    s = subset_scores(ROWS, WEIGHTS, ACTIONS, 3, BELIEFS, HEAD, 0.75)
    for q in range(len(ROWS)):
        named = ROWS[q][ROWS[q] >= 0]
        lab = row_labels(ACTIONS[named], BELIEFS[named], HEAD, 3, 0.75)
        assert np.allclose(s[q], WEIGHTS[q][:len(named)] @ lab, rtol=0, atol=1e-12)
    # only the named rows are read: changing another row's belief changes nothing
    other = BELIEFS.copy()
    other[[q for q in range(5) if q not in ROWS]] = 99.0
    assert np.array_equal(subset_scores(ROWS, WEIGHTS, ACTIONS, 3, other, HEAD, 0.75), s)
    # fully smoothed: the weighted belief probabilities of the rows
    one = subset_scores(ROWS, WEIGHTS, ACTIONS, 3, BELIEFS, HEAD, 1.0)
    assert np.allclose(one[0], 0.7 * _softmax_by_hand(BELIEFS[3])
                       + 0.3 * _softmax_by_hand(BELIEFS[0]), rtol=0, atol=1e-12)


def test_the_smoothing_is_the_default_only_where_it_was_measured():
    assert ROW_SMOOTHING == 0.75
    assert default_row_smoothing(True, "per_action") == ROW_SMOOTHING
    assert default_row_smoothing(True, "nearest") == 0.0      # the paper's k nearest rows
    assert default_row_smoothing(False, "per_action") == 0.0  # continuous imitation
