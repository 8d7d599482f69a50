"""The compiled Wolfe iteration: the reference QP's residual, problem by problem, batch-independent."""

from __future__ import annotations

import numpy as np

from aoc_cli.decompose.minnorm import min_norm_point
from aoc_cli.decompose.reference import reference_residual


def test_each_problem_matches_the_reference_and_does_not_depend_on_the_batch():
    rng = np.random.default_rng(11)
    d, k = 6, 14
    B = rng.standard_normal((9, k, d))
    Y = np.vstack([
        B[:3].mean(axis=1),  # inside the hull: residual 0
        B[3:6, 0] + 3.0 * rng.standard_normal((3, d)),  # outside: a face or a vertex
        B[6:, :4].mean(axis=1) + 1e-3 * rng.standard_normal((3, d)),  # near the boundary
    ])
    valid = np.ones((9, k), bool)
    valid[6:, 10:] = False  # padded problems: fewer neighbours
    P = B - Y[:, None, :]
    out = min_norm_point(P, valid)
    assert out.ok.all()
    for q in range(9):
        c = valid[q]
        ref = reference_residual(B[q, c], Y[q])
        scale = np.linalg.norm(P[q, c], axis=1).max()
        assert abs(out.residual[q] - ref) <= 1e-6 * ref + 1e-7 * scale
        w = out.weights[q]
        assert (w >= 0).all() and abs(w.sum() - 1) < 1e-12 and (w[~c] == 0).all()
        x = w @ P[q]
        assert (P[q, c] @ x >= x @ x - 1e-9 * scale**2).all()  # the optimality condition
        assert abs(np.linalg.norm(x) - out.residual[q]) <= 1e-12 * scale
        # solved alone: the same weights, bit for bit (no lockstep across the batch)
        alone = min_norm_point(P[q : q + 1], valid[q : q + 1])
        np.testing.assert_array_equal(alone.weights[0], w)
    assert (out.residual[:3] < 1e-9).all() and (out.residual[3:6] > 0.1).all()
    assert out.iterations >= 1
