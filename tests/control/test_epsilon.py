"""Step 4's candidate filter is one rule: the controller's decision and ``aoc evaluate``'s
batch of held-out steps keep the same candidates (aoc_cli.control.epsilon)."""

import numpy as np
import pytest

from aoc_cli.control.epsilon import epsilon_filter, residual_cap


def _one_step(residual, epsilon, cap):
    """The controller's filter of one step, written out as it was before it was shared."""
    threshold = float(np.quantile(residual, epsilon))
    if cap is not None:
        threshold = min(threshold, cap)
    passed = residual <= threshold + 1e-12 * max(1.0, threshold)
    if not passed.any():
        threshold = float(residual.min())
        passed = residual <= threshold + 1e-12 * max(1.0, threshold)
    return threshold, passed


@pytest.mark.parametrize("cap", [None, 0.05, 1e-9])
@pytest.mark.parametrize("epsilon", [0.1, 0.5, 1.0])
def test_a_batch_of_steps_keeps_what_each_step_alone_keeps(epsilon, cap):
    rng = np.random.default_rng(3)
    residual = rng.exponential(0.1, size=(40, 25))
    residual[5, :] = 0.2          # all equal: every candidate passes
    residual[7, :3] = 0.0         # ties at the bottom
    threshold, passed = epsilon_filter(residual, epsilon, cap)
    assert threshold.shape == (40, 1) and passed.shape == (40, 25)
    for row in range(len(residual)):
        t, p = _one_step(residual[row], epsilon, cap)
        assert threshold[row, 0] == t
        assert (passed[row] == p).all()


def test_a_cap_under_every_residual_keeps_the_smallest_ones():
    residual = np.array([[0.3, 0.1, 0.1, 0.5]])
    threshold, passed = epsilon_filter(residual, 0.5, cap=0.01)
    assert threshold[0, 0] == 0.1
    assert passed.tolist() == [[False, True, True, False]]


def test_the_residual_cap_is_c_times_the_typical_p90():
    assert residual_cap(3.0, 0.5) == 1.5
    assert residual_cap(None, 0.5) is None and residual_cap(3.0, None) is None
