"""Every script of benchmarks/ still starts: its ``--help`` exits 0 and prints its usage (a
script whose imports broke in a move fails here, not months later)."""

import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
SCRIPTS = sorted((ROOT / "benchmarks").glob("*/*.py"))


def test_the_scripts_are_grouped_into_perf_ab_and_notes():
    assert SCRIPTS and {p.parent.name for p in SCRIPTS} == {"perf", "ab", "notes"}
    assert not list((ROOT / "benchmarks").glob("*.py"))


@pytest.mark.parametrize("script", SCRIPTS, ids=lambda p: f"{p.parent.name}/{p.name}")
def test_every_benchmark_script_answers_help(script):
    env = {**os.environ, "PYTHONPATH": str(ROOT), "OMP_NUM_THREADS": "1"}
    proc = subprocess.run([sys.executable, str(script), "--help"], capture_output=True,
                          text=True, env=env, cwd=ROOT, timeout=300)
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert "usage:" in proc.stdout.lower()
