"""A store holding a corpus of every built-in task and of every ingest fixture, and a few
made to hold what round trips lose first (action labels, patient ids, no rewards, truncated
and unflagged episode ends, unsorted tag labels, NaN columns)."""

from __future__ import annotations

import json

import numpy as np

from aoc_cli.formats import ReadOptions, ingest
from aoc_cli.store import CorpusData, Store, discrete_space, episode_starts_from_lengths
from tests.formats.sources import (d3rlpy_episodes, flat_arrays, write_csv, write_d3rlpy,
                                   write_d4rl, write_minari)

TASK_STEPS = 160


def _patients(ids=("p10", "p2", "p7"), lengths=(4, 3, 5), seed=0):
    rng = np.random.default_rng(seed)
    rows = []
    for pid, t in zip(ids, lengths):
        for step in range(t):
            rows.append([pid, step, round(rng.normal(80, 5), 3), rng.normal(120, 9),
                         int(rng.integers(0, 3)), round(rng.normal(), 4),
                         "icu" if pid != "p2" else "ward", rng.normal()])
    return rows


def labelled() -> CorpusData:
    """Discrete actions with labels, patient ids out of sorted order, no rewards, one
    episode truncated and one that ends with neither flag, tag labels not sorted."""
    rng = np.random.default_rng(3)
    lengths = [5, 3, 6, 2]
    n = sum(lengths)
    starts = episode_starts_from_lengths(lengths)
    terminals = np.zeros(n, bool)
    truncations = np.zeros(n, bool)
    terminals[starts[1] - 1] = True
    truncations[starts[2] - 1] = True
    terminals[starts[4] - 1] = True  # episode 2 ends with neither flag
    space = discrete_space(4, names=["none", "low", "mid", "high"])  # one label an action
    return CorpusData(
        observations=rng.standard_normal((n, 3)).astype(np.float32),
        actions=rng.integers(0, 3, n), rewards=None, terminals=terminals,
        truncations=truncations, episode_starts=starts,
        observation_space={"type": "box", "shape": [3], "names": ["hr", "bp", "x[0]"]},
        action_space=space,
        tags={"arm": (rng.integers(0, 2, n).astype(np.int32), ["treated", "control", "unused"])},
        columns={"score": np.where(rng.random(n) < 0.2, np.nan, rng.standard_normal(n))},
        episode_ids=["z9", "a1", "m5", "b2"], source={"kind": "test"})


def build(root, scratch, minari_root) -> list[str]:
    """Write the corpora into ``Store(root)`` (sources in ``scratch``); return their names."""
    from aoc_cli.envs import TASKS, collect

    store = Store(root)
    names = []
    for task in TASKS:
        data, _ = collect(task, steps=TASK_STEPS, seed=1)
        store.write(task, data)
        names.append(task)

    def put(name, path, **options):
        ingest(path, name, store=store, options=ReadOptions(**options))
        names.append(name)

    arrays, _ = flat_arrays(n=120, ends=((29, "t"), (59, "o"), (99, "t")))
    rng = np.random.default_rng(5)
    infos = {"score": rng.standard_normal(120), "policy": rng.integers(0, 3, 120)}
    put("fixture-d4rl", write_d4rl(scratch / "f.hdf5", arrays, infos), tag_columns=["policy"])
    np.savez(scratch / "f.npz", **arrays)
    put("fixture-npz", scratch / "f.npz")
    put("fixture-d3rlpy", write_d3rlpy(scratch / "c.h5", d3rlpy_episodes()))
    put("fixture-d3rlpy-discrete",
        write_d3rlpy(scratch / "d.h5", d3rlpy_episodes(discrete=True), tuple_obs=True))
    write_minari("fixture/dict-v0")
    put("fixture-minari-dict", minari_root / "fixture" / "dict-v0")
    write_minari("fixture/box-v0", dict_obs=False, discrete=False, infos=True)
    put("fixture-minari-box", minari_root / "fixture" / "box-v0", tag_columns=["policy"])
    header = ["id", "t", "obs_hr", "obs_bp", "act_dose", "reward", "ward", "lab"]
    log = write_csv(scratch / "log.csv", header, _patients())
    static = write_csv(scratch / "static.csv", ["id", "age", "sex"],
                       [["p7", 71, "F"], ["p10", 45.5, "M"], ["p2", 60, "F"]])
    put("fixture-csv", log, static=static, discrete_actions=True, tag_columns=["ward"])
    put("fixture-csv-reward-free", log, reward_free=True)
    mapping = scratch / "roles.json"
    mapping.write_text(json.dumps({"observations": ["obs_*", "lab"], "actions": ["act_dose"]}))
    put("fixture-csv-mapped", log, columns_file=mapping)
    store.write("labelled", labelled())
    names.append("labelled")
    # appended: tag labels in order of appearance, a column NaN where one part lacks it
    put("appended", write_d4rl(scratch / "a.hdf5", arrays), tags={"site": "north"})
    ingest(scratch / "f.hdf5", "appended", store=store, append=True,
           options=ReadOptions(tags={"site": "east"}, tag_columns=["policy"]))
    return names
