"""Store changes made for ingest speed: contiguous float columns read through a memory map
when large, and the fast finiteness check."""

import numpy as np

import aoc_cli.store.reader as store_mod
from aoc_cli.store import Store
from aoc_cli.store.corpus import all_finite
from tests.store.test_store import make_data


def test_large_float_columns_are_memory_mapped_and_histories_equal(tmp_path, monkeypatch):
    data = make_data(lengths=(30, 50, 20), d_o=3)
    Store(tmp_path).write("c", data)
    monkeypatch.setattr(store_mod, "IN_MEMORY_BYTES", 64)  # every column counts as large
    corpus = Store(tmp_path).corpus("c")
    obs = corpus.observations
    assert isinstance(obs, np.memmap)
    np.testing.assert_array_equal(obs, data.observations)
    rows = np.array([99, 3, 45, 45, 0])
    np.testing.assert_array_equal(corpus.read("observations", rows), data.observations[rows])
    h = corpus.history(rows, 4)
    monkeypatch.setattr(store_mod, "IN_MEMORY_BYTES", 2 << 30)
    ref = Store(tmp_path).corpus("c").history(rows, 4)
    for a, b in zip(h, ref):
        np.testing.assert_array_equal(a, b)
    # flags and step counters stay compressed (chunked), so they are read, not mapped
    assert not isinstance(corpus.read("timesteps"), np.memmap)


def test_all_finite_fast_path_does_not_mistake_overflow_for_nan():
    big = np.full(10, 3e38, np.float32)  # the float32 sum overflows to inf
    assert all_finite(big)
    big[7] = np.nan
    assert not all_finite(big)
    assert not all_finite(np.array([1.0, -np.inf]))
    assert all_finite(np.arange(5))
