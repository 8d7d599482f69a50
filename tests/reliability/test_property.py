"""Property test (hypothesis): generated malformed CSV, D4RL HDF5 and NPZ files and JSONL
queries fed to the readers through the real CLI entry point. Each input either becomes a
valid corpus (every recorded checksum verifies) or fails with exit 2 and exactly one
``aoc: error:`` line (warnings aside), the store byte for byte unchanged: no internal error,
no traceback, no half-written corpus.

Few examples per format (the suite must stay fast); ``AOC_RELIABILITY_EXAMPLES=N`` runs N
each and ``AOC_RELIABILITY_REPORT=FILE`` writes the tally (docs/reliability.md).
"""

from __future__ import annotations

import atexit
import contextlib
import io
import json
import os
import shutil
import sys
import tempfile
from collections import Counter
from pathlib import Path

import h5py
import numpy as np
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from tests.reliability.common import snapshot

EXAMPLES = int(os.environ.get("AOC_RELIABILITY_EXAMPLES", "12"))
SETTINGS = settings(max_examples=EXAMPLES, deadline=None, derandomize=True,
                    suppress_health_check=list(HealthCheck))
TALLY: Counter = Counter()


def _report() -> None:
    path = os.environ.get("AOC_RELIABILITY_REPORT")
    if path and TALLY:
        Path(path).write_text(json.dumps(dict(sorted(TALLY.items())), indent=2) + "\n")


atexit.register(_report)


def run(*args: str) -> tuple[int, str, str]:
    """``aoc ARGS`` in this process (the real entry point): (code, stdout, stderr)."""
    from aoc_cli.cli.app import main

    out, err = io.StringIO(), io.StringIO()
    code = 0
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        try:
            main(list(args))
        except SystemExit as exit_:
            code = exit_.code if isinstance(exit_.code, int) else 1
    return code, out.getvalue(), err.getvalue()


def check_ingest(kind: str, write) -> None:
    """Write an input with ``write(folder) -> path`` and ingest it into a store that already
    holds a corpus: a valid corpus, or one error line and the store unchanged."""
    from aoc_cli.store import Store
    from aoc_cli.store.verify import verify_corpus

    folder = Path(tempfile.mkdtemp(prefix="aoc-prop-"))
    try:
        store = folder / "store"
        base = folder / "base.npz"
        np.savez(base, observations=np.zeros((3, 1)), actions=np.zeros((3, 1)))
        assert run("--store", str(store), "ingest", str(base), "--name", "base")[0] == 0
        path = write(folder)
        for name, extra in (("new", ()), ("base", ("--append",))):
            before = snapshot(store)
            code, out, err = run("--store", str(store), "ingest", str(path), "--name", name,
                                 *extra)
            lines = err.strip().splitlines()
            assert "Traceback" not in err and "internal error" not in err, err
            errors = [ln for ln in lines if ln.startswith("aoc: error: ")]
            assert all(ln.startswith(("aoc: error: ", "aoc: warning: ")) for ln in lines), err
            if code == 0:
                TALLY[f"{kind}: valid corpus"] += 1
                corpus = Store(store).corpus(name)
                assert corpus.n_rows > 0 and not errors
                rows = verify_corpus(Store(store), name)
                assert {r["status"] for r in rows} == {"ok"}, rows
            else:
                TALLY[f"{kind}: clean error"] += 1
                assert code == 2 and len(errors) == 1 and out == "", (code, out, err)
                assert snapshot(store) == before, "a failed ingest changed the store"
            TALLY[f"{kind}: inputs tried"] += 1
    finally:
        shutil.rmtree(folder, ignore_errors=True)


CELLS = st.one_of(st.integers(-3, 3).map(str), st.floats(allow_nan=True).map(str),
                  st.sampled_from(["", " ", "nan", "inf", "-inf", "abc", "1e400", "2024-01-01",
                                   "\"", "a,b", "\t", "é", "0x10", "1_000", "\x00"]),
                  st.text(max_size=4))
HEADER = ["episode", "t", "obs_0", "obs_1", "act_0", "reward"]


@st.composite
def csv_text(draw) -> str:
    """A valid log (2-4 episodes), then 0-3 drawn mutations: a hostile cell, a dropped or
    renamed column, a row with a field more or less, repeated rows, another separator."""
    header = list(HEADER)
    rows = []
    for e in range(draw(st.integers(2, 4))):
        for t in range(draw(st.integers(1, 4))):
            rows.append([str(e), str(t), f"{0.1 * t:.2f}", str(e), str(t % 2), "1.5"])
    sep = ","
    for _ in range(draw(st.integers(0, 3))):
        if not rows:  # an "empty" mutation cut every row: nothing left to mutate
            break
        kind = draw(st.sampled_from(["cell", "cell", "drop", "rename", "width", "repeat",
                                     "sep", "empty"]))
        r = draw(st.integers(0, len(rows) - 1))
        c = draw(st.integers(0, len(header) - 1))
        if kind == "cell":
            rows[r][c] = draw(CELLS)
        elif kind == "drop" and len(header) > 1:
            del header[c]
            rows = [row[:c] + row[c + 1:] for row in rows]
        elif kind == "rename":
            header[c] = draw(st.sampled_from(["", "id", "time", "obs_0", "x", "act_1"]))
        elif kind == "width":
            rows[r] = rows[r] + ["1"] if draw(st.booleans()) else rows[r][:-1]
        elif kind == "repeat":
            rows.insert(r, list(rows[r]))
        elif kind == "sep":
            sep = draw(st.sampled_from(["\t", ";"]))
        else:
            rows = rows[:r]
    return "\n".join([sep.join(header)] + [sep.join(row) for row in rows]) + "\n"


@SETTINGS
@given(text=csv_text(), gz=st.booleans(), cut=st.integers(0, 200))
def fed_malformed_csv(text, gz, cut):
    def write(folder):
        path = folder / ("log.csv.gz" if gz else "log.csv")
        data = text.encode("utf-8", "surrogatepass")
        if gz:
            data = gzip_bytes(data)
            data = data[:max(10, len(data) - cut)] if cut % 3 == 0 else data
        path.write_bytes(data)
        return path

    check_ingest("csv", write)


def gzip_bytes(data: bytes) -> bytes:
    import gzip

    return gzip.compress(data)


@st.composite
def flat_arrays(draw) -> dict:
    """Valid D4RL arrays, then 0-3 drawn mutations: a key dropped, a length, shape or dtype
    changed (strings, 3-d), a NaN or inf, an extra ``infos/`` column."""
    n = draw(st.integers(1, 12))
    out = {"observations": np.arange(n * 3, dtype="f4").reshape(n, 3) / 7,
           "actions": (np.arange(n) % 2).astype("f4")[:, None],
           "rewards": np.ones(n), "terminals": np.arange(n) % 5 == 4,
           "timeouts": np.zeros(n, bool)}
    for _ in range(draw(st.integers(0, 3))):
        key = draw(st.sampled_from(sorted(out)))
        kind = draw(st.sampled_from(["drop", "length", "strings", "nan", "inf", "3d", "int",
                                     "info", "empty"]))
        arr = out[key]
        if arr.dtype.kind == "S" and kind in ("nan", "inf", "int"):
            continue  # already strings: nothing numeric to change
        if kind == "drop":
            del out[key]
            if not out:
                break
        elif kind == "length":
            out[key] = arr[:-1] if draw(st.booleans()) else np.concatenate([arr, arr[:1]])
        elif kind == "strings":
            out[key] = np.full(arr.shape, b"ab")
        elif kind in ("nan", "inf"):
            out[key] = arr.astype("f8")
            out[key].flat[draw(st.integers(0, arr.size - 1)) if arr.size else 0:][:1] = \
                np.nan if kind == "nan" else np.inf
        elif kind == "3d":
            out[key] = np.repeat(arr.reshape(len(arr), -1)[:, None], 2, axis=1)
        elif kind == "int":
            out[key] = (np.asarray(arr, "f8") * 3).astype("i8")
        elif kind == "info":
            out["infos/cost"] = np.arange(n + draw(st.integers(-1, 1)), dtype="f8")
        else:
            out[key] = arr[:0]
    return out


@SETTINGS
@given(arrays=flat_arrays(), flip=st.one_of(st.just(-1), st.just(-1), st.integers(0, 3000)))
def fed_malformed_d4rl_hdf5(arrays, flip):
    def write(folder):
        path = folder / "data.hdf5"
        with h5py.File(path, "w") as f:
            for key, arr in arrays.items():
                f[key] = arr
        if flip >= 0:  # one damaged byte somewhere in the file
            data = bytearray(path.read_bytes())
            data[flip % len(data)] ^= 0xFF
            path.write_bytes(bytes(data))
        return path

    check_ingest("d4rl", write)


@SETTINGS
@given(arrays=flat_arrays(), cut=st.one_of(st.just(-1), st.just(-1), st.integers(0, 400)))
def fed_malformed_npz(arrays, cut):
    def write(folder):
        path = folder / "data.npz"
        np.savez(path, **{k.replace("/", "_"): v for k, v in arrays.items()})
        if cut >= 0:  # truncated archive
            data = path.read_bytes()
            path.write_bytes(data[:cut % max(1, len(data))])
        return path

    check_ingest("npz", write)


JSON_VALUES = st.recursive(
    st.one_of(st.none(), st.booleans(), st.integers(-5, 5), st.floats(), st.text(max_size=3)),
    lambda inner: st.lists(inner, max_size=4) | st.dictionaries(st.text(max_size=3), inner,
                                                                max_size=3),
    max_leaves=10)


NUMBER = st.floats(-10, 10, allow_nan=False)


@st.composite
def jsonl_query(draw):
    """A valid query (observation of 2 numbers, history of 5-number steps), then maybe one
    field replaced by any JSON value."""
    query = {"observation": draw(st.lists(NUMBER, min_size=2, max_size=2)),
             "history": draw(st.lists(st.lists(NUMBER, min_size=4, max_size=4), max_size=3))}
    if draw(st.booleans()):
        query[draw(st.sampled_from(["observation", "history", "action"]))] = draw(JSON_VALUES)
    if draw(st.integers(0, 5)) == 0:
        query = draw(JSON_VALUES)
    return query


@SETTINGS
@given(query=jsonl_query(), raw=st.integers(0, 9))
def fed_malformed_jsonl_queries(query, raw):
    """The explain query reader: an AocError (one line) or a query of the right shapes."""
    from types import SimpleNamespace

    from aoc_cli.explanation.decisions import parse_query
    from aoc_cli.errors import AocError

    corpus = SimpleNamespace(name="m", observation_dim=2, action_dim=1, discrete=False)
    line = json.dumps(query) if raw else json.dumps(query)[:-1]  # one in ten cut short
    TALLY["jsonl: inputs tried"] += 1
    try:
        obs, hist, _a, _c = parse_query(line, 1, corpus, 3)
    except AocError as err:
        assert "\n" not in str(err)
        TALLY["jsonl: clean error"] += 1
        return
    TALLY["jsonl: valid query"] += 1
    assert obs.shape == (2,) and np.isfinite(obs).all() and hist.mask.shape == (1, 3)


def _fed(kind: str, property_test) -> None:
    """Run one format's property test and check that its inputs reached the reader (a
    strategy that generated nothing, or a test body that returned early, would pass silently).
    Each check is in the test it checks: xdist may run the formats on different workers."""
    tried = TALLY[f"{kind}: inputs tried"]
    property_test()
    assert TALLY[f"{kind}: inputs tried"] > tried


def test_malformed_csv():
    _fed("csv", fed_malformed_csv)


def test_malformed_d4rl_hdf5():
    _fed("d4rl", fed_malformed_d4rl_hdf5)


def test_malformed_npz():
    _fed("npz", fed_malformed_npz)


def test_malformed_jsonl_queries():
    _fed("jsonl", fed_malformed_jsonl_queries)
