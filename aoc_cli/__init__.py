"""aoc: accountable offline control.

Every decision is backed by a small, named set of rows of a logged dataset (the decision
corpus), with weights and a corpus residual that says how far the decision had to extrapolate.
The library gives the same functions the ``aoc`` commands call (:mod:`aoc_cli.api`, one
entry per command, re-exported here: ``aoc_cli.train(...)``, ``aoc_cli.open_session(...)``).
"""

__version__ = "0.1.0"

from aoc_cli.errors import AocError  # noqa: E402
from aoc_cli.lazy import exports  # noqa: E402

#: The entries of :mod:`aoc_cli.api`, loaded on first use (PEP 562): ``import aoc_cli`` and
#: ``aoc --help`` stay light (no torch, FAISS or environments until an entry is called).
API = ("ingest", "split", "collect", "train", "build_index", "open_session", "rollout",
       "explain", "explain_queries", "explain_recorded", "explain_logged", "explain_steps",
       "evaluate", "bench", "verify", "export", "tasks", "info", "corpora")

#: The library's types, loaded the same way: the store, the settings of a model and of its
#: controller, the session a notebook works in and the results it shows.
TYPES = ("Store", "BeliefConfig", "ControllerConfig", "Session", "Decision", "Explained",
         "Evaluation")

__all__ = ["AocError", "__version__", *API, *TYPES]

# each name is aoc_cli.api's, loaded on first use (aoc_cli.lazy): import aoc_cli loads no entry
# (tests/test_api.py)
__getattr__, __dir__ = exports(__name__, {name: "api" for name in API + TYPES})
