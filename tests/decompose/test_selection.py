"""Row selection and derived indexes seen through the decomposition."""

from __future__ import annotations

import numpy as np

from aoc_cli.decompose import decompose
from aoc_cli.index.search import BeliefIndex


def test_with_a_row_mask_no_returned_row_is_outside_it():
    rng = np.random.default_rng(0)
    beliefs = rng.standard_normal((3000, 4)).astype(np.float32)
    tags = rng.integers(0, 3, 3000)
    queries = beliefs[:40] + 0.05 * rng.standard_normal((40, 4))
    index = BeliefIndex.build(beliefs, kind="flat")
    for tag in range(3):
        mask = tags == tag
        result = decompose(beliefs, queries, index=index, selection=mask)
        used = result.rows >= 0
        assert mask[result.rows[used]].all()
        assert mask[result.neighbours[result.neighbours >= 0]].all()
        # the same as decomposing the selected rows alone
        alone = decompose(beliefs[mask], queries)
        np.testing.assert_allclose(result.residual, alone.residual, rtol=1e-6, atol=1e-9)


def test_selection_smaller_than_k_pads_the_neighbours():
    rng = np.random.default_rng(1)
    beliefs = rng.standard_normal((200, 3)).astype(np.float32)
    rows = np.array([3, 17, 50])
    result = decompose(beliefs, rng.standard_normal((5, 3)), selection=rows)
    assert set(result.neighbours[result.neighbours >= 0].tolist()) <= set(rows.tolist())
    assert (result.neighbours[:, 3:] == -1).all()
    assert np.isin(result.rows[result.rows >= 0], rows).all()


def test_a_resampled_index_decomposes_into_corpus_rows():
    rng = np.random.default_rng(2)
    beliefs = rng.standard_normal((500, 3)).astype(np.float32)
    heavy = np.zeros(500)
    heavy[:250] = 4.0  # rows 0..249 four times, the rest dropped
    index = BeliefIndex.build(beliefs, kind="flat").resample(heavy)
    queries = rng.standard_normal((10, 3))
    result = decompose(beliefs, queries, index=index)
    used = result.rows >= 0
    assert (result.rows[used] < 250).all()
    gaps = np.linalg.norm(beliefs[np.maximum(result.rows, 0)] - queries[:, None, :], axis=-1)
    np.testing.assert_allclose(result.distance[used], gaps[used], rtol=1e-6)
    # four copies of each row among the neighbours, never two copies in the subset
    assert all(len(set(r[r >= 0].tolist())) == int((r >= 0).sum()) for r in result.rows)
