"""The pool certificate (index.pooled.within_pool), used by the centroid search and by each
group's search: a certified query's k nearest rows are all inside the pool."""

import numpy as np

from aoc_cli.index.search.pooled import within_pool


def test_a_certified_query_has_its_k_nearest_rows_inside_the_pool():
    rng = np.random.default_rng(0)
    V = rng.normal(size=(4000, 5))
    centre = np.zeros(5)
    Y = rng.normal(scale=0.3, size=(300, 5))
    k, kp = 10, 400
    d_centre = ((V - centre) ** 2).sum(1)
    pool = np.argsort(d_centre)[:kp]
    pool_d2 = float(d_centre[pool[-1]])
    d2_all = ((Y[:, None, :] - V[None]) ** 2).sum(-1)  # (Q, N)
    kth_in_pool = np.sort(d2_all[:, pool], axis=1)[:, k - 1]
    ok = within_pool(kth_in_pool, Y, centre, pool_d2)
    assert 0 < ok.sum() < len(Y)  # the test sees both answers
    nearest = np.argsort(d2_all, axis=1)[:, :k]
    inside = np.isin(nearest, pool).all(axis=1)
    assert inside[ok].all()  # never a false certificate
    # far queries are not certified
    far = within_pool(kth_in_pool[:3], Y[:3] + 10.0, centre, pool_d2)
    assert not far.any()
