"""Every script of benchmarks/ still starts (its ``--help`` exits 0 and prints its usage: a
script whose imports broke in a move fails here, not months later), and the perf scripts'
shared harness (benchmarks/perf/_harness.py) measures what its rows say: a few scripts run end
to end on a tiny size, their JSON rows checked against the work they were given."""

import importlib.util
import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
SCRIPTS = sorted(p for p in (ROOT / "benchmarks").glob("*/*.py") if not p.name.startswith("_"))
PERF = ROOT / "benchmarks" / "perf"


def _harness():
    spec = importlib.util.spec_from_file_location("_harness", PERF / "_harness.py")
    module = importlib.util.module_from_spec(spec)
    sys.modules.setdefault("_harness", module)  # its dataclass looks its module up there
    spec.loader.exec_module(module)
    return module


def _run(script: Path, *args: str, timeout: int = 300) -> subprocess.CompletedProcess:
    env = {**os.environ, "PYTHONPATH": str(ROOT), "OMP_NUM_THREADS": "1"}
    return subprocess.run([sys.executable, str(script), *args], capture_output=True,
                          text=True, env=env, cwd=ROOT, timeout=timeout)


def test_the_scripts_are_grouped_into_perf_ab_and_notes():
    assert SCRIPTS and {p.parent.name for p in SCRIPTS} == {"perf", "ab", "notes"}
    assert not list((ROOT / "benchmarks").glob("*.py"))


@pytest.mark.parametrize("script", SCRIPTS, ids=lambda p: f"{p.parent.name}/{p.name}")
def test_every_benchmark_script_answers_help(script):
    proc = _run(script, "--help")
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert "usage:" in proc.stdout.lower()


def test_every_perf_script_runs_on_the_harness():
    for script in PERF.glob("[!_]*.py"):
        text = script.read_text()
        assert "import _harness as h" in text, script.name
        assert "sys.path" not in text and "argparse.ArgumentParser(" not in text, script.name


def test_interleaved_cases_alternate_and_pair_their_rounds():
    h = _harness()
    order = []
    runs = h.interleave({"a": lambda i: order.append(("a", i)),
                         "b": lambda i: order.append(("b", i))}, 4)
    assert order == [("a", 0), ("b", 0), ("b", 1), ("a", 1), ("a", 2), ("b", 2), ("b", 3),
                     ("a", 3)]
    assert len(runs["a"].wall) == len(runs["b"].cpu) == 4
    base, other = h.Runs([1.0, 2.0, 4.0], [0, 0, 0]), h.Runs([3.0, 2.0, 2.0], [0, 0, 0])
    assert h.paired(base, other) == 1.0  # the rounds' ratios 3, 1, 0.5: median 1
    row = h.row("x", 10, base, extra=1)
    assert row["median_s"] == 2.0 and row["per_s"] == 5.0 and row["runs"] == 3
    assert row["extra"] == 1 and h.parse_size("1.5m") == 1_500_000 and h.sizes("2k,3") == [
        2000, 3]


def _rows(proc) -> list[dict]:
    assert proc.returncode == 0, proc.stderr[-3000:]
    rows = json.loads(proc.stdout)
    for r in rows:
        assert r["median_s"] > 0 and r["cpu_s"] >= 0
        if r["work"] is not None:
            assert r["per_s"] == pytest.approx(r["work"] / r["median_s"], rel=1e-12)
    return rows


def test_collect_benchmark_rows_count_the_rows_collected():
    rows = _rows(_run(PERF / "collect.py", "--repeats", "2", "--pendulum-rows", "700",
                      "--tasks", "pendulum-het,two-gates", "-f", "json"))
    by = {r["case"]: r for r in rows}
    assert by["pendulum-het"]["work"] == 700 and by["pendulum-het"]["runs"] == 2
    assert by["two-gates"]["work"] > 500  # 500 episodes of several steps each


def test_export_benchmark_reads_every_export_back_as_the_same_corpus():
    """Also the harness's ``aoc`` process: the command's row times a fresh process."""
    rows = _rows(_run(PERF / "export.py", "--repeats", "1", "--rows", "3000",
                      "--other-rows", "1000", "-f", "json"))
    assert [r["case"] for r in rows] == ["d4rl, library", "d4rl, aoc export (process)",
                                         "minari, library", "csv, library", "d4rl, library"]
    assert [r["work"] for r in rows] == [3000, 3000, 1000, 1000, 1000]
    assert all(r["same_hash"] is True for r in rows[1:])
    # the command's process (start, imports, write) takes longer than the library call
    assert rows[1]["median_s"] > rows[0]["median_s"]


def test_corpus_ready_makes_each_missing_piece_once_through_the_api(tmp_path):
    """The store of the perf scripts: the corpus, model and index as aoc collect, aoc train
    and aoc index make them, and nothing made again when present."""
    from aoc_cli.belief import list_models
    from aoc_cli.store import DEFAULT_INDEX, DEFAULT_MODEL, index_dir

    h = _harness()
    settings = dict(train=dict(paper=True, seed=0, max_epochs=1, patience=1, threads=1),
                    index={})
    corpus = h.corpus_ready(tmp_path, "p", "pendulum-het", steps=400, seed=0, **settings)
    assert corpus.n_rows == 400 and list_models(corpus) == [DEFAULT_MODEL]
    built = index_dir(corpus.path, DEFAULT_MODEL, DEFAULT_INDEX)
    stamps = {p: p.stat().st_mtime_ns for p in (corpus.path / "corpus.h5", built)}
    again = h.corpus_ready(tmp_path, "p", "pendulum-het", steps=400, seed=0, **settings)
    assert again.hash == corpus.hash
    assert {p: p.stat().st_mtime_ns for p in stamps} == stamps


def test_decompose_benchmark_with_exact_search_recalls_every_neighbour():
    """A flat (exact) index finds the exact search's neighbours: recall 1 in every query."""
    rows = _rows(_run(PERF / "decompose.py", "--sizes", "2k", "--kind", "flat", "--batches",
                      "2", "--repeats", "2", "--paper-batches", "0", "--recall-batches", "2",
                      "--threads", "1", "-f", "json"))
    assert len(rows) == 1 and rows[0]["rows"] == 2000 and rows[0]["kind"] == "flat"
    assert rows[0]["work"] == 100 and rows[0]["runs"] == 4  # 2 batches x 2 repeats
    assert rows[0]["recall"] == 1.0 and rows[0]["min_recall"] == 1.0
    assert rows[0]["ratio"] == pytest.approx(rows[0]["plain_ms"] / rows[0]["ms"])
