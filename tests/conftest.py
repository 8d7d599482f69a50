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
    """Run the real ``aoc`` entry point in a process of its own: (returncode, stdout, stderr).

    Forked from a server that has imported the heavy libraries (:mod:`tests.cli_child`), or a
    fresh interpreter where the environment given differs from this one's outside ``AOC_*``
    (``PYTHONPATH``, thread settings: read when an interpreter starts or a library loads)."""
    env = dict(os.environ if env is None else env)
    fresh = {k for k in set(env) | set(os.environ)
             if env.get(k) != os.environ.get(k) and not k.startswith("AOC_")}
    if fresh or sys.platform != "linux":
        proc = subprocess.run(
            [sys.executable, "-c", "from aoc_cli.cli.app import main; main()", *args],
            capture_output=True, text=True, input=input, env=env, cwd=cwd,
        )
        return proc.returncode, proc.stdout, proc.stderr
    import tempfile

    from tests import cli_child

    with tempfile.TemporaryDirectory(prefix="aoc-cmd-") as tmp:
        out, err = os.path.join(tmp, "out"), os.path.join(tmp, "err")
        stdin = None
        if input is not None:
            stdin = os.path.join(tmp, "in")
            with open(stdin, "w", encoding="utf-8") as f:
                f.write(input)
        proc = _forks().Process(target=cli_child.run,
                                args=(list(args), env, None if cwd is None else str(cwd),
                                      stdin, out, err))
        proc.start()
        proc.join()
        code = proc.exitcode
        with open(out, encoding="utf-8", errors="replace") as f:
            stdout = f.read()
        with open(err, encoding="utf-8", errors="replace") as f:
            stderr = f.read()
    return code, stdout, stderr


_FORKS = None


def _forks():
    """The forkserver context whose server has imported :data:`tests.cli_child.PRELOAD`,
    started here, with OMP_WAIT_POLICY as the ``aoc`` command sets it before its imports."""
    global _FORKS
    if _FORKS is None:
        import multiprocessing
        from multiprocessing import forkserver

        from tests import cli_child

        ctx = multiprocessing.get_context("forkserver")
        ctx.set_forkserver_preload([*cli_child.PRELOAD, "tests.cli_child"])
        before = os.environ.get("OMP_WAIT_POLICY")
        os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")
        try:
            forkserver.ensure_running()
        finally:
            if before is None:
                os.environ.pop("OMP_WAIT_POLICY", None)
        _FORKS = ctx
    return _FORKS


@pytest.fixture
def aoc():
    return run_aoc


def run_in_process(capsys, *args: str):
    """The real entry point ``aoc_cli.cli.app.main`` in this process: (code, stdout, stderr).

    Same code path as the console script (argument parsing, AocError -> one line + exit 2),
    without a Python start and the imports per call.
    """
    from aoc_cli.cli.app import main

    capsys.readouterr()
    code = 0
    try:
        main(list(args))
    except SystemExit as exit_:
        code = exit_.code if isinstance(exit_.code, int) else (0 if exit_.code is None else 1)
    out, err = capsys.readouterr()
    return code, out, err


@pytest.fixture
def aoc_inproc(capsys):
    """Run ``aoc ARGS...`` in this process: ``aoc_inproc("info", "x") -> (code, out, err)``."""
    return lambda *args: run_in_process(capsys, *args)


@pytest.fixture(scope="session")
def small_maze(tmp_path_factory):
    """A small maze store (120 episodes, value mode, continuous actions, tag ``policy``), its
    model and index, built once per test process (explanations, what-if, pages)."""
    from aoc_cli.belief import BeliefConfig, train_model
    from aoc_cli.envs import collect
    from aoc_cli.index import build_index
    from aoc_cli.store import Store

    store = Store(tmp_path_factory.mktemp("small-maze") / "store")
    data, _ = collect("maze", episodes=120, seed=0)
    corpus = store.write("maze", data)
    train_model(corpus, BeliefConfig(seed=0, threads=1, max_epochs=6, patience=3), "default")
    build_index(corpus)
    return store


def pytest_configure(config):
    config.addinivalue_line(
        "markers", "quality: an end-to-end quality test of a built-in task (collect, train, "
                   "index, rollout; tens of seconds): spread over the collection order so that "
                   "pytest-xdist's workers share them")
    config.addinivalue_line(
        "markers", "long_setup: a module whose shared fixture takes minutes: collected first, "
                   "so that one pytest-xdist worker starts it at once while the other takes "
                   "the rest (longest first)")


def pytest_collection_modifyitems(session, config, items):
    """The ``long_setup`` modules first, then the ``quality`` tests placed evenly among the
    others, a module's together (its fixture built once, on one worker): pytest-xdist hands
    each worker runs of consecutive tests, and the slow ones side by side would all go to one
    worker. Deterministic, so every worker collects the same order."""
    first = [item for item in items if item.get_closest_marker("long_setup")]
    if first:  # their module's items stay together (one fixture), ahead of everything
        items[:] = first + [item for item in items if not item.get_closest_marker("long_setup")]
    heavy: dict = {}            # module -> its quality items, in collection order
    for item in items[len(first):]:
        if item.get_closest_marker("quality"):
            heavy.setdefault(item.nodeid.split("::")[0], []).append(item)
    groups = list(heavy.values())
    rest = [item for item in items[len(first):] if not item.get_closest_marker("quality")]
    if not groups or not rest:
        return
    gap = len(rest) / len(groups)
    spread, j = [], 0
    for i, item in enumerate(rest):
        while j < len(groups) and int(gap * (j + 0.5)) <= i:
            spread.extend(groups[j])
            j += 1
        spread.append(item)
    items[:] = first + spread + [item for group in groups[j:] for item in group]
