"""The harness the benchmarks/perf scripts share: their arguments, the store they measure on
(built through the public API, :mod:`aoc_cli.api`), repeated runs with medians, paired runs in
one process, and the rows they print.

A script imports it first (``import _harness as h``: Python puts the script's folder on the
path, so ``python benchmarks/perf/X.py`` from the repository root finds it); the import sets
``OMP_WAIT_POLICY=PASSIVE`` as the ``aoc`` command does (aoc_cli/threads.py), before anything
loads OpenMP. Then:

* ``h.parser(__doc__, repeats=5)``: the script's argparse parser with ``--repeats`` and
  ``--format table|json`` (a markdown table, or a JSON list of the rows);
* ``h.repeat(fn, n)`` / ``h.interleave({case: fn}, n)``: ``fn(i)`` run ``n`` times (``i`` the
  run index, a script's seed), wall and CPU seconds of each run; interleaved cases run round by
  round (a, b, a, b, ...) so that a load change on the shared machine hits them alike, and
  ``h.paired(a, b)`` is the median of the rounds' own ratios;
* ``h.aoc(args, store)``: the ``aoc`` command in a fresh process (its start and imports
  counted: what a user waits for), wall and CPU seconds;
* ``h.corpus_ready(store, name, task, ...)``: the corpus, its model and its index, each made
  by the API entry of its command (``collect``, ``train``, ``build_index``) when missing;
* ``h.drive(session, task, steps, decide)``: a rollout of the controller, each step's
  ``decide(observation, history)`` the caller's to time;
* ``h.row(case, work, runs, unit)``: one result row (the work done, the median, the rate,
  every run) and ``h.emit(rows, fmt)`` prints them.
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import statistics
import subprocess
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable

os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")  # as the aoc command (aoc_cli/threads.py)

#: The repository root (the folder above benchmarks/).
ROOT = Path(__file__).resolve().parents[2]


def omp_threads(n: int = 1) -> None:
    """``OMP_NUM_THREADS=n`` unless the environment sets it (call before numpy, torch and
    FAISS load: their pools read it once)."""
    os.environ.setdefault("OMP_NUM_THREADS", str(n))


def parse_size(text: str) -> int:
    """``"100k"`` -> 100000, ``"1.5m"`` -> 1500000, ``"300"`` -> 300."""
    text = text.strip().lower()
    mult = {"k": 1_000, "m": 1_000_000}.get(text[-1], 1)
    return int(float(text.rstrip("km")) * mult)


def sizes(text: str) -> list[int]:
    """A comma-separated ``--sizes`` list, each through :func:`parse_size`."""
    return [parse_size(s) for s in text.split(",") if s.strip()]


def parser(doc: str, *, repeats: int | None = None,
           rows: bool = True) -> argparse.ArgumentParser:
    """The script's parser: its docstring's first line as description, ``--repeats`` (runs of
    each case; the median is reported) when ``repeats`` is given, and ``--format`` for a
    script that prints :func:`emit`'s rows (``rows``)."""
    ap = argparse.ArgumentParser(description=doc.strip().splitlines()[0])
    if repeats is not None:
        ap.add_argument("--repeats", type=int, default=repeats,
                        help=f"runs of each case, median reported (default {repeats})")
    if rows:
        ap.add_argument("--format", "-f", choices=("table", "json"), default="table",
                        help="the result rows as a markdown table or a JSON list")
    return ap


@dataclass
class Runs:
    """Wall and CPU seconds (of this process, or of the child for :func:`aoc`) and the
    output of each run."""

    wall: list[float] = field(default_factory=list)
    cpu: list[float] = field(default_factory=list)
    outs: list = field(default_factory=list)

    def add(self, wall: float, cpu: float, out: Any = None) -> None:
        self.wall.append(wall)
        self.cpu.append(cpu)
        self.outs.append(out)

    @property
    def out(self) -> Any:
        """The last run's output."""
        return self.outs[-1] if self.outs else None

    @property
    def median(self) -> float:
        return statistics.median(self.wall)

    @property
    def cpu_median(self) -> float:
        return statistics.median(self.cpu)


def timed(fn: Callable[[], Any]) -> tuple[Any, float, float]:
    """(fn's output, wall seconds, CPU seconds of this process, every thread, and of the
    children it waited for: FQE's forked parts)."""
    w, c, k = time.perf_counter(), time.process_time(), _children_cpu()
    out = fn()
    return out, time.perf_counter() - w, time.process_time() - c + _children_cpu() - k


def _children_cpu() -> float:
    t = os.times()
    return t.children_user + t.children_system


def repeat(fn: Callable[[int], Any], repeats: int) -> Runs:
    """``fn(i)`` for i = 0 .. repeats - 1, each timed."""
    runs = Runs()
    for i in range(repeats):
        out, wall, cpu = timed(lambda: fn(i))
        runs.add(wall, cpu, out)
    return runs


def interleave(cases: dict[str, Callable[[int], Any]], repeats: int) -> dict[str, Runs]:
    """Every case once a round, ``repeats`` rounds, the order reversed every other round (a,
    b, b, a, ...): paired runs under about the same load."""
    runs = {name: Runs() for name in cases}
    for i in range(repeats):
        order = list(cases) if i % 2 == 0 else list(cases)[::-1]
        for name in order:
            out, wall, cpu = timed(lambda: cases[name](i))
            if isinstance(out, Runs):  # a child process timed itself (aoc)
                wall, cpu, out = out.wall[0], out.cpu[0], out.out
            runs[name].add(wall, cpu, out)
    return runs


def paired(base: Runs, other: Runs) -> float:
    """The median over rounds of other / base (wall seconds of the same round)."""
    return statistics.median(o / b for b, o in zip(base.wall, other.wall))


def aoc(args: list[str], store: str | os.PathLike | None = None,
        env: dict | None = None) -> Runs:
    """The ``aoc`` command with ``args`` in a fresh Python process of this interpreter, this
    repository first on the path: one run (wall seconds, CPU seconds of the child: user +
    system), its stdout as ``out``. A failure ends the script with the command's stderr."""
    full = {**os.environ, "PYTHONPATH": os.pathsep.join(
        [str(ROOT), *filter(None, [os.environ.get("PYTHONPATH")])]), **(env or {})}
    store_args = [] if store is None else ["--store", str(store)]
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    proc = subprocess.run([sys.executable, "-c", "from aoc_cli.cli.app import main; main()",
                           *store_args, *args], capture_output=True, text=True, env=full)
    wall = time.perf_counter() - t0
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    if proc.returncode != 0:
        raise SystemExit(f"aoc {' '.join(args)} failed: {proc.stderr.strip()[-2000:]}")
    runs = Runs()
    runs.add(wall, (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime),
             proc.stdout)
    return runs


def corpus_ready(store, name: str, task: str | None = None, *, steps: int | None = None,
                 episodes: int | None = None, seed: int = 0, train: dict | None = None,
                 index: dict | None = None, model: str | None = None,
                 rebuild_index: bool = False):
    """Corpus ``name`` of ``store`` (a Store or a folder), made as the commands make it, each
    step only when missing: ``aoc_cli.api.collect(task, ...)`` (``steps`` / ``episodes``,
    ``seed``); with ``train`` (``aoc_cli.api.train``'s settings), model ``model`` (default
    DEFAULT_MODEL); with ``index`` (``aoc_cli.api.build_index``'s settings), the index
    ``index["index_id"]`` (default DEFAULT_INDEX) on that model (``rebuild_index``: built again
    even when present). Returns the Corpus."""
    import aoc_cli
    from aoc_cli.belief import list_models
    from aoc_cli.store import DEFAULT_INDEX, DEFAULT_MODEL, Store, index_dir

    store = store if isinstance(store, Store) else Store.open(store)
    model = model or DEFAULT_MODEL
    if not store.exists(name):
        aoc_cli.collect(task, name, store=store, steps=steps, episodes=episodes, seed=seed)
    corpus = store.corpus(name)
    if train is not None and model not in list_models(corpus):
        aoc_cli.train(name, store=store, model=model, **train)
    index_id = (index or {}).get("index_id", DEFAULT_INDEX)
    if index is not None and (rebuild_index
                              or not index_dir(corpus.path, model, index_id).is_dir()):
        aoc_cli.build_index(name, model, store=store, **index)
    return store.corpus(name)


def drive(session, task: str, steps: int, decide: Callable, seed: int = 1) -> None:
    """``steps`` steps of ``task``'s environment from ``reset(seed)`` with the actions of
    ``decide(observation, history)`` (a Decision; ``history`` as the controller keeps it, one
    row), a new episode started where one ends: a rollout whose steps the caller times."""
    import numpy as np

    from aoc_cli.control import HistoryBuffer
    from aoc_cli.envs import make_env

    corpus = session.corpus
    env = make_env(task)
    buf = HistoryBuffer(session.model.history_length, corpus.observation_dim,
                        corpus.action_dim, corpus.discrete)
    obs, _ = env.reset(seed=seed)
    for _ in range(steps):
        d = decide(obs, buf.history())
        nxt, r, term, trunc, _ = env.step(np.asarray(d.action, np.float32))
        buf.push(obs, d.action, r)
        obs = nxt
        if term or trunc:
            buf.reset()
            obs, _ = env.reset()


def row(case: str, work: int | None, runs: Runs, unit: str = "rows", **extra) -> dict:
    """One result: ``case``, the ``work`` each run did (a count of ``unit``; None: none to
    count), the median wall seconds, ``work`` per second at the median, the median CPU
    seconds, the number of runs and (up to 12) every run's wall seconds, and ``extra``
    columns. The row goes to stderr at once
    too (one JSON line), so a long run shows its results as they come."""
    out = {"case": case, "work": work, "unit": unit if work is not None else None,
           "median_s": runs.median, "per_s": None if work is None else work / runs.median,
           "cpu_s": runs.cpu_median, "runs": len(runs.wall),
           "runs_s": [round(w, 4) for w in runs.wall] if len(runs.wall) <= 12 else None,
           **extra}
    print(json.dumps(out), file=sys.stderr, flush=True)
    return out


def _cell(v: Any) -> str:
    if isinstance(v, float):
        return f"{v:.4g}" if abs(v) < 1e3 else f"{v:.0f}"
    if isinstance(v, (list, tuple)):
        return ", ".join(_cell(x) for x in v)
    return "" if v is None else str(v)


def emit(rows: list[dict], fmt: str = "table", file=None) -> None:
    """Print ``rows``: a markdown table (the columns of every row, in order of first
    appearance) or, with ``fmt="json"``, a JSON list."""
    file = file or sys.stdout
    if fmt == "json":
        print("[\n" + ",\n".join(json.dumps(r) for r in rows) + "\n]", file=file, flush=True)
        return
    cols = list(dict.fromkeys(k for r in rows for k in r))
    print("| " + " | ".join(cols) + " |", file=file)
    print("|" + " --- |" * len(cols), file=file)
    for r in rows:
        print("| " + " | ".join(_cell(r.get(c)) for c in cols) + " |", file=file, flush=True)


def memory() -> dict:
    """VmHWM (the peak resident memory) and VmRSS of this process, MB."""
    out = {}
    for line in Path("/proc/self/status").read_text().splitlines():
        key, _, value = line.partition(":")
        if key in ("VmHWM", "VmRSS"):
            out[key] = int(value.split()[0]) / 1024
    return out


def load() -> float:
    """The 1-minute load average (the machine is shared: printed beside timings)."""
    return os.getloadavg()[0]
