"""Explanations of decisions beyond the record: what changes without some rows (``what_if``,
:mod:`aoc_cli.control.whatif`) and the best action not chosen (``contrast``,
:mod:`aoc_cli.control.contrast`).

:func:`explain_decisions` turns the decisions of one query into records
(:func:`aoc_cli.control.decision_record`) with these keys added; ``aoc explain`` calls it for
every kind of query (JSONL queries, a logged step, a step of an audit log).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from aoc_cli.control.contrast import contrast_record
from aoc_cli.control.controller import Decision
from aoc_cli.control.records import decision_record
from aoc_cli.control.whatif import Removal, redecide, what_if_record
from aoc_cli.store import History

if TYPE_CHECKING:
    from aoc_cli.session import Session


def explain_decisions(session: Session, observation: np.ndarray, history: History,
                      decisions: list[Decision], selection: np.ndarray | None = None,
                      removal: Removal | None = None, step: int | None = None) -> list[dict]:
    """One record per decision of the query (``observation`` (d_o,), ``history`` one row),
    each with its ``contrast`` (the best action not chosen, or None); ``selection`` the (N,)
    bool row mask the decisions were made with (None: the controller's own); ``removal``:
    also re-decide without those rows (``what_if``)."""
    corpus, index = session.corpus, session.index
    typical = index.typical_residual
    ctl = session.controller
    records = [decision_record(d, corpus, index, step=step, observation=observation,
                               typical_residual=typical) for d in decisions]
    for d, rec in zip(decisions, records):
        rec["contrast"] = contrast_record(ctl, observation, history, d, corpus, index,
                                          selection, typical)
    if removal is not None:
        keep = removal.keep(ctl.selection if selection is None else selection)
        for d, rec in zip(decisions, records):
            after = redecide(ctl, observation, history, d, keep)
            rec["what_if"] = what_if_record(
                rec, decision_record(after, corpus, index, step=step, observation=observation,
                                     typical_residual=typical), removal, corpus)
    return records
