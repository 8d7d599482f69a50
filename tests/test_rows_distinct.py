"""aoc_cli.rows.distinct_rows against numpy's np.unique(axis=0): the same distinct rows, each
row mapped back to its own, the first occurrence of each kept."""

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from aoc_cli.rows import distinct_rows


@settings(max_examples=200, deadline=None)
@given(arrays(np.float32, st.tuples(st.integers(0, 30), st.integers(1, 3)),
              elements=st.sampled_from([0.0, 1.0, -2.5, 3.0])))
def test_distinct_rows_are_numpys_unique_rows(a):
    first, inverse = distinct_rows(a)
    assert first.dtype == inverse.dtype == np.int64 and len(inverse) == len(a)
    np.testing.assert_array_equal(a[first][inverse], a)
    assert len(first) == (len(np.unique(a, axis=0)) if len(a) else 0)
    for u, row in enumerate(first):        # the first occurrence of each distinct row
        assert row == np.flatnonzero(inverse == u)[0]


def test_a_one_column_array_is_rows_of_one():
    first, inverse = distinct_rows(np.array([3, 1, 3, 2], np.int64))
    assert inverse.tolist() == [2, 0, 2, 1] and first.tolist() == [1, 3, 0]
