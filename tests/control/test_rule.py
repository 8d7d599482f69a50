"""The decision rule is one function: the controller's decision (one step) and ``aoc
evaluate``'s batch of held-out steps keep the same candidates and choose the same one
(aoc_cli.control.rule)."""

import numpy as np
import pytest

from aoc_cli.control import controller as controller_module
from aoc_cli.control.config import ControllerConfig
from aoc_cli.control.rule import choose, epsilon_filter, residual_cap
from aoc_cli.control.support import penalised, support_filter
from aoc_cli.evaluation import score


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


def _controller_before(residual, value, config, cap, support, value_std):
    """The controller's steps 4-5 of one step as written before the rule was shared: sort by
    v_hat (or the penalised v_hat) descending, then residual ascending; the first that
    passes."""
    threshold, passed = epsilon_filter(residual, config.epsilon, cap)
    key = value
    if config.min_support is not None or config.support_penalty is not None:
        passed = support_filter(passed, support, config.min_support)
        key = penalised(value, support, config.support_penalty, value_std)
    order = np.lexsort((residual, -key))
    return float(threshold[0]), passed, int(next(i for i in order if passed[i]))


def _steps(seed: int, s: int = 60, k: int = 12):
    """Residuals, values and supports of S steps with ties in each."""
    rng = np.random.default_rng(seed)
    residual = np.round(rng.exponential(0.1, size=(s, k)), 2)  # ties on the residual
    value = np.round(rng.normal(size=(s, k)), 1)               # ties on v_hat
    value[3] = 0.5                                             # every v_hat equal
    residual[4] = 0.2                                          # every residual equal
    value[5], residual[5] = 0.5, 0.2                           # both: the first candidate
    support = rng.integers(1, 30, size=(s, k)).astype(np.float64)
    return residual, value, support


@pytest.mark.parametrize("settings", [{}, {"epsilon": 0.2}, {"epsilon": 1.0},
                                      {"residual_cap": 0.5}, {"min_support": 12.0},
                                      {"support_penalty": 2.0},
                                      {"min_support": 40.0, "support_penalty": 1.0}])
def test_a_batch_of_steps_chooses_what_each_step_alone_chooses_as_the_controller_did(
        settings):
    config = ControllerConfig(**settings)
    cap = residual_cap(config.residual_cap, 0.05)
    for seed in range(4):
        residual, value, support = _steps(seed)
        threshold, passed, chosen = choose(residual, value, config, cap=cap, support=support,
                                           value_std=0.7)
        assert chosen.shape == (len(residual),) and passed.shape == residual.shape
        for i in range(len(residual)):
            t, p, c = choose(residual[i:i + 1], value[i:i + 1], config, cap=cap,
                             support=support[i:i + 1], value_std=0.7)
            assert (t[0, 0], c[0]) == (threshold[i, 0], chosen[i])
            assert (p[0] == passed[i]).all()
            before = _controller_before(residual[i], value[i], config, cap, support[i], 0.7)
            assert before[0] == threshold[i, 0] and before[2] == chosen[i]
            assert (before[1] == passed[i]).all()
    if config.support_penalty is None:  # all tied: the first that passes
        assert chosen[5] == np.flatnonzero(passed[5])[0]


def test_the_controller_and_evaluate_call_the_one_rule():
    assert controller_module._choose is choose and score.choose is choose
