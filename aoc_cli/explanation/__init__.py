"""The decision's explanation: what supports a decision and what would change it.

- :mod:`aoc_cli.explanation.decisions`: decisions explained from their sources (JSONL
  queries, a logged step, a decision an audit log recorded), each with its supporting rows,
  weights and residual, and the audit's OOD band;
- :mod:`aoc_cli.explanation.whatif`: the decision again without some rows (``--without``);
- :mod:`aoc_cli.explanation.contrast`: the best action not chosen and why;
- :mod:`aoc_cli.explanation.attribution`: SimplEx's Jacobian projection of a supporting row;
- :mod:`aoc_cli.explanation.pages`: the explained decisions as the HTML pages of
  :mod:`aoc_cli.report` (``--html``).

Names are imported lazily (PEP 562): the explanation loads torch (the attributions) only when
it is used. (The room is not named ``explain``: that is the API's entry,
``aoc_cli.explain``, which a subpackage of that name would hide once imported.)
"""

from __future__ import annotations

from aoc_cli.lazy import exports

_WHERE = {
    "explain_logged_step": "decisions",
    "explain_queries": "decisions",
    "explain_query": "decisions",
    "explain_recorded": "decisions",
    "parse_query": "decisions",
    "replay_decision": "decisions",
}

__all__ = sorted(_WHERE)


__getattr__, __dir__ = exports(__name__, _WHERE)
