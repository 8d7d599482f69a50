"""aoc: accountable offline control.

Every decision is backed by a small, named set of rows of a logged dataset (the decision
corpus), with weights and a corpus residual that says how far the decision had to extrapolate.
The library gives the same functions the ``aoc`` commands call (:mod:`aoc_cli.api`, one
entry per command, re-exported here: ``aoc_cli.train(...)``, ``aoc_cli.open_session(...)``).
"""

__version__ = "0.1.0"

from aoc_cli.errors import AocError  # noqa: E402

#: The entries of :mod:`aoc_cli.api`, loaded on first use (PEP 562): ``import aoc_cli`` and
#: ``aoc --help`` stay light (no torch, FAISS or environments until an entry is called).
API = ("ingest", "split", "collect", "train", "build_index", "open_session", "rollout",
       "explain", "explain_queries", "explain_recorded", "explain_logged", "explain_steps",
       "evaluate", "bench", "verify", "export", "tasks", "info", "corpora")

__all__ = ["AocError", "__version__", *API]


def __getattr__(name: str):
    if name in API:
        from aoc_cli import api  # lazy: import aoc_cli loads no entry (tests/test_api.py)

        return getattr(api, name)
    raise AttributeError(f"module 'aoc_cli' has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(API))
