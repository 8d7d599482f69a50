"""Shared test fixtures: a temporary store, and a CLI runner that returns (code, stdout, stderr)."""

from __future__ import annotations

import os
import subprocess
import sys

# Two pytest workers share two cores: one thread each for torch, FAISS and BLAS.
os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("MKL_NUM_THREADS", "1")

import pytest


@pytest.fixture
def store(tmp_path, monkeypatch):
    """A fresh, empty store folder, also exported as AOC_STORE."""
    root = tmp_path / "store"
    monkeypatch.setenv("AOC_STORE", str(root))
    return root


def run_aoc(*args: str, input: str | None = None, env=None, cwd=None):
    """Run the real ``aoc`` entry point in a subprocess: (returncode, stdout, stderr)."""
    proc = subprocess.run(
        [sys.executable, "-c", "from aoc_cli.cli.app import main; main()", *args],
        capture_output=True, text=True, input=input, env=env, cwd=cwd,
    )
    return proc.returncode, proc.stdout, proc.stderr


@pytest.fixture
def aoc():
    return run_aoc
