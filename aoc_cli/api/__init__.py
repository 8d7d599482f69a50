"""The library's public API: one entry per ``aoc`` command, each doing the command's whole
job (locks, existence checks, settings, the session) and returning data, never printing.

>>> import aoc_cli
>>> aoc_cli.collect("two-gates", "gates", episodes=40, store="corpora")     # doctest: +SKIP
>>> aoc_cli.train("gates", store="corpora", belief={"max_epochs": 20})    # doctest: +SKIP
>>> aoc_cli.build_index("gates", store="corpora")                         # doctest: +SKIP
>>> session = aoc_cli.open_session("gates", store="corpora", env="two-gates")  # doctest: +SKIP
>>> session.explain(data="gates", episode=0, step=3)                   # doctest: +SKIP

Every entry takes ``store=``: a :class:`aoc_cli.store.Store`, a folder, or None (``$AOC_STORE``,
else ``./corpora``). ``progress=``: an :class:`aoc_cli.progress.Progress` callable; ``log=``:
a function of one line of text, for the notes a command prints on stderr. Errors are
:class:`aoc_cli.errors.AocError`. The ``aoc`` commands parse their options, make one call
here and print what it returns (aoc_cli/cli/); docs/design.md, "Library API", lists them.
The entries live in data.py (ingest, info, verify, export), collection.py (collect, tasks),
model.py (train, build_index), control.py (open_session, rollout), session.py (the Session
open_session returns: explain and evaluate on what it loaded), explanation.py (explain
and its entries per source, Explained), evaluation.py (evaluate, Evaluation), common.py (the
types Store, ControllerConfig, BeliefConfig)
and experiment.py (bench), each loaded when its entry is first used. No module here is named
after an entry: importing a submodule binds its name in this package, which would hide the
entry of that name.
"""

from __future__ import annotations

from aoc_cli.lazy import exports

#: Where each public name lives; loaded on first use (PEP 562), so that a command imports only
#: what its entry needs (``aoc info`` no torch, FAISS or matplotlib).
_WHERE = {
    "ingest": "data", "split": "data", "tasks": "collection", "collect": "collection", "info": "data", "corpora": "data",
    "verify": "data", "export": "data", "Verified": "data",
    "train": "model", "build_index": "model", "Indexed": "model",
    "open_session": "control", "rollout": "control", "RolledOut": "control",
    "explain": "explanation", "explain_queries": "explanation",
    "explain_recorded": "explanation", "explain_logged": "explanation",
    "explain_steps": "explanation", "Explained": "explanation",
    "evaluate": "evaluation", "Evaluation": "evaluation",
    "Store": "common", "ControllerConfig": "common", "BeliefConfig": "common",
    "Session": "session", "Decision": "session",
    "bench": "experiment", "Benched": "experiment",
}

__all__ = sorted(_WHERE)


__getattr__, __dir__ = exports(__name__, _WHERE)
