"""The library's public API: one entry per ``aoc`` command, each doing the command's whole
job (locks, existence checks, settings, the session) and returning data, never printing.

>>> import aoc_cli
>>> aoc_cli.collect("two-gates", "gates", episodes=40, store="corpora")     # doctest: +SKIP
>>> aoc_cli.train("gates", store="corpora", max_epochs=20)                 # doctest: +SKIP
>>> aoc_cli.build_index("gates", store="corpora")                         # doctest: +SKIP
>>> session = aoc_cli.open_session("gates", store="corpora", env="two-gates")  # doctest: +SKIP

Every entry takes ``store=``: a :class:`aoc_cli.store.Store`, a folder, or None (``$AOC_STORE``,
else ``./corpora``). ``progress=``: an :class:`aoc_cli.progress.Progress` callable; ``log=``:
a function of one line of text, for the notes a command prints on stderr. Errors are
:class:`aoc_cli.errors.AocError`. The ``aoc`` commands parse their options, make one call
here and print what it returns (aoc_cli/cli/); docs/design.md, "Library API", lists them.
The entries live in data.py (ingest, collect, info, verify, export), model.py (train,
build_index), control.py (open_session, rollout), explain.py, evaluate.py and bench.py.
"""

from aoc_cli.api.bench import Benched, bench
from aoc_cli.api.control import RolledOut, open_session, rollout
from aoc_cli.api.data import (Verified, collect, corpora, export, info, ingest, tasks,
                              verify)
from aoc_cli.api.evaluate import evaluate
from aoc_cli.api.explain import Explained, explain
from aoc_cli.api.model import Indexed, build_index, train

__all__ = ["Benched", "Explained", "Indexed", "RolledOut", "Verified", "bench", "build_index",
           "collect", "corpora", "evaluate", "explain", "export", "info", "ingest",
           "open_session", "rollout", "tasks", "train", "verify"]
