"""`aoc bench --workers`: the cells as Ray tasks give the rows of a serial run; a failing cell
is retried once and then reported; finished cells are kept and taken by a re-run; without
--workers nothing imports Ray."""

from __future__ import annotations

import csv
import os
import subprocess
import sys
from pathlib import Path

import pytest
import ray

from aoc_cli.experiments.cells import Cell, Plan
from aoc_cli.experiments.execute import execute
from aoc_cli.experiments.common import Context
from aoc_cli.experiments.methods import Budget, Runner
from aoc_cli.experiments.prepare import Artefacts
from aoc_cli.experiments.results import result_row

#: Runs the CLI in a fresh interpreter and reports whether Ray was imported.
PROBE = ("import sys\nfrom aoc_cli.cli.app import main\ntry:\n    main(sys.argv[1:])\n"
         "except SystemExit as e:\n    code = e.code\nelse:\n    code = 0\n"
         "print('RAY_IMPORTED', 'ray' in sys.modules, file=sys.stderr)\nsys.exit(code)\n")


def _bench(tmp_path, out, *extra):
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(
        [str(Path(__file__).resolve().parents[2]), os.environ.get("PYTHONPATH", "")])}
    env.pop("RAY_ADDRESS", None)
    proc = subprocess.run([sys.executable, "-c", PROBE, "bench", "two-gates", "--tiny",
                           "--bench-store", str(tmp_path / "store"), "--out", str(out),
                           "--format", "json", *extra],
                          capture_output=True, text=True, env=env, cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr[-2000:]
    with open(out / "results.csv", newline="") as f:
        rows = list(csv.DictReader(f))
    return rows, proc.stdout, proc.stderr


def _without_timing(rows):
    return [{k: v for k, v in r.items() if k != "seconds_per_step"} for r in rows]


def test_workers_give_the_serial_rows_and_the_serial_path_never_imports_ray(tmp_path):
    serial, serial_table, err = _bench(tmp_path, tmp_path / "serial")
    assert "RAY_IMPORTED False" in err
    # the Ray run prepares the artefacts itself (a fresh store) and runs the cells on 2 workers
    (tmp_path / "store").rename(tmp_path / "store-serial")
    ray_rows, ray_table, err = _bench(tmp_path, tmp_path / "ray", "--workers", "2")
    assert "RAY_IMPORTED True" in err
    assert len(serial) == 2 and all(r["status"] == "ok" for r in serial)
    assert _without_timing(ray_rows) == _without_timing(serial)
    assert ray_table == serial_table                       # the printed table too
    assert len(list((tmp_path / "ray" / "cells").glob("*.json"))) == 2
    # a re-run takes the finished cells: no Ray started, the same rows
    again, again_table, err = _bench(tmp_path, tmp_path / "ray", "--workers", "2")
    assert "2 of 2 cells kept" in err and "RAY_IMPORTED False" in err
    assert again == ray_rows and again_table == ray_table


# -- a plan whose cells fail: retried once, then reported -----------------------------------

def _cells(ctx, scale):
    return [Cell("t", "m", f"cell={i}", 0, ("p",), (i,)) for i in range(3)]


def _prepare(ctx, scale, prep):
    return None


def _run(ctx, scale, cell, prepared):
    (i,) = cell.args
    marker = Path(ctx.out) / f"attempted-{i}"
    first = not marker.exists()
    marker.touch()
    if i == 1 and first:
        raise RuntimeError("a flaky cell")
    if i == 2:
        os._exit(3)  # the worker process dies, every time
    return {"rows": [result_row("x", cell.task, cell.method, cell.setting, cell.seed,
                                return_mean=float(i))]}


FLAKY = Plan(_cells, _prepare, _run, lambda ctx, scale: (lambda row: None))


@pytest.fixture
def local_ray():
    ray.cloudpickle.register_pickle_by_value(sys.modules[__name__])
    yield
    ray.shutdown()


def test_a_failed_cell_is_retried_once_then_reported_and_not_kept(tmp_path, local_ray):
    out = tmp_path / "out"
    out.mkdir()
    messages = []
    ctx = Context("x", "tiny", out, Artefacts(tmp_path / "store"), Runner(Budget()), [0],
                  log=messages.append)
    rows = execute(FLAKY, ctx, {}, workers=2)
    assert [r["setting"] for r in rows] == ["cell=0", "cell=1", "cell=2"]
    assert [r["status"] for r in rows] == ["ok", "ok", "failed"]
    assert [r["return_mean"] for r in rows[:2]] == [0.0, 1.0]
    assert "RuntimeError: a flaky cell" in " ".join(messages)
    assert any("cell=2" in m and "failed twice" in m for m in messages)
    assert rows[2]["note"]
    # the two finished cells are kept, the failed one is not: a re-run tries it alone again
    assert len(list((out / "cells").glob("*.json"))) == 2
    messages.clear()
    again = execute(FLAKY, ctx, {}, workers=2)
    assert "2 of 3 cells kept" in " ".join(messages)
    assert again[:2] == rows[:2] and again[2]["status"] == "failed"


def test_workers_must_be_positive(aoc, tmp_path):
    code, _out, err = aoc("bench", "two-gates", "--tiny", "--workers", "0",
                          "--bench-store", str(tmp_path / "s"), "--out", str(tmp_path / "o"))
    assert code == 2 and err.strip().splitlines()[-1].startswith("aoc: error: --workers")
