"""What the reliability tests share: a store snapshot, the one-line-error check, real
processes of the aoc entry point, and small corpora."""

from __future__ import annotations

import os
import re
import subprocess
import sys

import numpy as np

from tests.cli.test_ingest import snapshot  # noqa: F401  (re-exported)
from tests.formats.sources import flat_arrays, write_d4rl

ENTRY = "from aoc_cli.cli.app import main; main()"


def one_line_error(code: int, out: str, err: str, pattern: str = "") -> str:
    """Exit 2, nothing on stdout, one ``aoc: error:`` line on stderr matching ``pattern``."""
    lines = err.strip().splitlines()
    assert code == 2, (code, out, err)
    assert len(lines) == 1 and lines[0].startswith("aoc: error: "), err
    assert "Traceback" not in err and "internal error" not in err, err
    assert re.search(pattern, lines[0]), (pattern, lines[0])
    return lines[0]


def spawn(*args: str, store, stdin=None) -> subprocess.Popen:
    """A real ``aoc ARGS`` process on ``store`` (stdout/stderr piped)."""
    env = dict(os.environ, AOC_STORE=str(store), OMP_NUM_THREADS="1")
    return subprocess.Popen([sys.executable, "-c", ENTRY, *args], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, stdin=stdin, text=True, env=env)


def python(code: str, store) -> subprocess.Popen:
    """A real Python process running ``code`` (stdin/stdout piped for a handshake)."""
    env = dict(os.environ, AOC_STORE=str(store), OMP_NUM_THREADS="1")
    return subprocess.Popen([sys.executable, "-c", code], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, stdin=subprocess.PIPE, text=True, env=env)


def d4rl_file(path, n: int = 400, seed: int = 0):
    """A D4RL-style HDF5 file of ``n`` rows (episodes of 100 steps)."""
    ends = tuple((r, "t") for r in range(99, n, 100))
    arrays, _ = flat_arrays(n=n, seed=seed, ends=ends)
    return write_d4rl(path, arrays)


def rows_of(store, name: str) -> int:
    from aoc_cli.store import Store

    return Store(store).corpus(name).n_rows


def flip_byte(path, offset: int) -> None:
    """Change one byte of a file in place (XOR 0x5A)."""
    with open(path, "r+b") as f:
        f.seek(offset)
        b = f.read(1)
        f.seek(offset)
        f.write(bytes([b[0] ^ 0x5A]))


def column_offset(path, key: str) -> int:
    """File offset of a contiguous HDF5 dataset's first byte."""
    import h5py

    with h5py.File(path, "r") as f:
        return int(f[key].id.get_offset())


__all__ = ["column_offset", "d4rl_file", "flip_byte", "one_line_error", "np", "python",
           "rows_of", "snapshot", "spawn"]
