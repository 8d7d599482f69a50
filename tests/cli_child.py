"""One ``aoc`` command in a process of its own, forked from a server that has already imported
the heavy libraries (torch, FAISS, numpy, scipy, numba, sklearn, pandas, ...): what ``python
-c "from aoc_cli.cli.app import main; main()" ARGS`` does, without its seconds of imports.

The suite runs a few hundred commands this way (``tests/conftest.py``: ``run_aoc``); a fresh
interpreter for each spent more of the suite's time in imports than in several of its quality
tests. The command's process is still its own (fresh state, its own file descriptors, its own
exit code): the server imports modules and nothing else; each command forks from it, takes the
caller's environment, working folder and stdin, writes its stdout and stderr to files, and
leaves with the command's exit code, as the console script would.
"""

from __future__ import annotations

import io
import os
import sys
import traceback

#: Imported once by the server (multiprocessing's forkserver), before any command forks.
PRELOAD = ["numpy", "scipy.sparse", "scipy.linalg", "torch", "faiss", "numba", "pandas",
           "pyarrow.csv", "pyarrow.parquet", "h5py", "matplotlib", "gymnasium",
           "sklearn.linear_model", "sklearn.metrics", "aoc_cli.cli.app"]


def run(args: list[str], env: dict, cwd: str | None, stdin: str | None, out: str,
        err: str) -> None:
    """Run ``aoc ARGS`` here, its stdout to ``out`` and stderr to ``err`` (paths), stdin from
    the file ``stdin`` (None: /dev/null); leave with its exit code."""
    fd = os.open(stdin or os.devnull, os.O_RDONLY)
    os.dup2(fd, 0)
    os.close(fd)
    for path, target in ((out, 1), (err, 2)):
        fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600)
        os.dup2(fd, target)
        os.close(fd)
    # as a fresh interpreter opens them on a pipe: UTF-8, stderr line-buffered
    sys.stdin = io.TextIOWrapper(io.FileIO(0, "r", closefd=False), encoding="utf-8")
    sys.stdout = io.TextIOWrapper(io.FileIO(1, "w", closefd=False), encoding="utf-8")
    sys.stderr = io.TextIOWrapper(io.FileIO(2, "w", closefd=False), encoding="utf-8",
                                  errors="backslashreplace", line_buffering=True)
    os.environ.clear()
    os.environ.update(env)
    if cwd is not None:
        os.chdir(cwd)
    sys.argv = ["-c", *args]
    sys.path.insert(0, "")                        # python -c: the working folder first
    code = 0
    try:
        from aoc_cli.cli.app import main

        main(list(args))
    except SystemExit as exit_:
        c = exit_.code
        code = c if isinstance(c, int) else (0 if c is None else 1)
        if not isinstance(c, int) and c is not None:
            print(c, file=sys.stderr)
    except BaseException:  # noqa: BLE001 - as the interpreter: the traceback, exit code 1
        traceback.print_exc()
        code = 1
    for stream in (sys.stdout, sys.stderr):
        try:
            stream.flush()
        except (OSError, ValueError):
            pass
    os._exit(code)
