"""aoc_cli.metrics's R^2 and MAE (numpy, to spare aoc evaluate scikit-learn's import) against
scikit-learn's r2_score and mean_absolute_error, the reference, on random and degenerate
cases."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays
from sklearn.metrics import mean_absolute_error, r2_score

from aoc_cli import metrics

finite = st.floats(-1e3, 1e3, allow_nan=False, width=64)


@settings(max_examples=200, deadline=None)
@given(st.integers(2, 40).flatmap(lambda n: st.tuples(
    arrays(np.float64, (n, 3), elements=finite), arrays(np.float64, (n, 3), elements=finite))))
def test_regression_matches_sklearn(pair):
    y, pred = pair
    got = metrics.regression(y, pred)
    want_r2 = r2_score(y, pred)
    if not np.isfinite(want_r2):            # a column of denormals: reported as null
        assert got["r2"] is None
    else:
        assert got["r2"] == pytest.approx(want_r2, rel=1e-9, abs=1e-9)
    assert got["mae"] == pytest.approx(mean_absolute_error(y, pred), rel=1e-12, abs=1e-12)


@pytest.mark.parametrize("target,v_hat", [
    ([1.0, 1.0, 1.0], [1.0, 1.0, 1.0]),        # constant, predicted exactly: 1
    ([1.0, 1.0, 1.0], [1.0, 2.0, 1.0]),        # constant, missed: 0
    ([0.0, 1.0, 2.0, 3.0], [0.1, 0.9, 2.2, 2.7]),
    ([0.0, 1.0], [1.0, 0.0]),                  # worse than the mean: negative
])
def test_value_fit_matches_sklearn(target, v_hat):
    got = metrics.value_fit(np.array(target), np.array(v_hat))
    assert got["value_r2"] == pytest.approx(r2_score(target, v_hat), rel=1e-12, abs=1e-12)
    assert got["value_mae"] == pytest.approx(mean_absolute_error(target, v_hat), rel=1e-12)


def test_regression_one_column_constant_averages_like_sklearn():
    y = np.array([[1.0, 0.0], [1.0, 1.0], [1.0, 2.0]])
    pred = np.array([[1.0, 0.5], [1.0, 1.0], [1.0, 1.5]])
    assert metrics.regression(y, pred)["r2"] == pytest.approx(r2_score(y, pred), rel=1e-12)


@settings(max_examples=200, deadline=None)
@given(st.integers(3, 40).flatmap(lambda n: st.tuples(
    arrays(np.float64, n, elements=st.sampled_from([0.0, 0.5, 1.0, 2.0, -3.0]) | finite),
    arrays(np.float64, n, elements=st.sampled_from([0.0, 1.0, 7.0]) | finite))))
def test_spearman_matches_scipy_with_ties(pair):
    from scipy.stats import spearmanr

    a, b = pair
    if np.ptp(a) == 0 or np.ptp(b) == 0:
        return
    assert metrics.spearman(a, b) == pytest.approx(spearmanr(a, b).statistic, rel=1e-9,
                                                  abs=1e-12)
