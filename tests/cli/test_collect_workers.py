"""`aoc collect --workers`: independently seeded chunks as Ray tasks; chunk i is exactly a
serial collect with chunk_seed(seed, i), and the corpus does not depend on the workers."""

from __future__ import annotations

import numpy as np

from aoc_cli.envs import collect
from aoc_cli.envs.chunked import chunk_seed, collect_chunked
from aoc_cli.store import Store


def _same(a, b):
    for key in ("observations", "actions", "rewards", "terminals", "truncations",
                "episode_starts"):
        np.testing.assert_array_equal(getattr(a, key), getattr(b, key))
    assert {k: list(v[1]) for k, v in a.tags.items()} == {k: list(v[1]) for k, v in b.tags.items()}
    for k in a.tags:
        np.testing.assert_array_equal(a.tags[k][0], b.tags[k][0])


def test_chunks_are_serial_collects_with_their_seeds_whatever_the_workers(store, aoc):
    serial, summary = collect_chunked("pendulum-het", steps=2500, seed=7, chunk_steps=1000)
    assert serial.n_rows == 2500
    assert [r["chunk"] for r in summary] == sorted(r["chunk"] for r in summary)
    assert {r["seed"] for r in summary} == {chunk_seed(7, i) for i in range(3)}
    # chunk i is collect(task, steps=its rows, seed=chunk_seed(7, i)); the corpus their concat
    parts = [collect("pendulum-het", steps=n, seed=chunk_seed(7, i))[0]
             for i, n in enumerate([1000, 1000, 500])]
    offsets = np.cumsum([0] + [p.n_rows for p in parts])
    for p, a, b in zip(parts, offsets, offsets[1:]):
        np.testing.assert_array_equal(serial.observations[a:b], p.observations)
        np.testing.assert_array_equal(serial.actions[a:b], p.actions)
    assert len(set(chunk_seed(7, i) for i in range(100))) == 100
    # the CLI on two Ray workers writes the same corpus
    code, _out, err = aoc("collect", "pendulum-het", "--steps", "2500", "--seed", "7",
                          "--name", "w", "--workers", "2", "--chunk", "1000", "--format", "json")
    assert code == 0, err
    _same(Store(store).corpus("w").load(), serial)


def test_workers_and_chunk_must_be_positive(store, aoc):
    for flag in ("--workers", "--chunk"):
        code, _out, err = aoc("collect", "pendulum-het", "--steps", "100", "--name", "x",
                              flag, "0")
        assert code == 2 and err.strip().splitlines()[-1].startswith(f"aoc: error: {flag}")
