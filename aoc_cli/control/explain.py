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

from aoc_cli.belief.attribution import NODES, feature_names, jacobian_projection
from aoc_cli.control.contrast import contrast_record
from aoc_cli.control.controller import Decision
from aoc_cli.control.monitor import OODMonitor, band_limits
from aoc_cli.control.records import decision_record
from aoc_cli.control.whatif import Removal, redecide, what_if_record
from aoc_cli.store import History

if TYPE_CHECKING:
    from aoc_cli.control.session import Session


def explain_decisions(session: Session, observation: np.ndarray, history: History,
                      decisions: list[Decision], selection: np.ndarray | None = None,
                      removal: Removal | None = None, step: int | None = None,
                      attribution: bool = True) -> list[dict]:
    """One record per decision of the query (``observation`` (d_o,), ``history`` one row),
    each with its ``contrast`` (the best action not chosen, or None); ``selection`` the (N,)
    bool row mask the decisions were made with (None: the controller's own); ``removal``:
    also re-decide without those rows (``what_if``); ``attribution``: each supporting row's
    feature attributions (:func:`attribute`)."""
    corpus, index = session.corpus, session.index
    typical = index.typical_residual
    ctl = session.controller
    records = [decision_record(d, corpus, index, step=step, observation=observation,
                               typical_residual=typical) for d in decisions]
    for d, rec in zip(decisions, records):
        rec["contrast"] = contrast_record(ctl, observation, history, d, corpus, index,
                                          selection, typical)
        if attribution:
            attribute(session, observation, history, d, rec)
            rec["query_history"] = _query_history(history)
    if removal is not None:
        keep = removal.keep(ctl.selection if selection is None else selection)
        for d, rec in zip(decisions, records):
            after = redecide(ctl, observation, history, d, keep)
            rec["what_if"] = what_if_record(
                rec, decision_record(after, corpus, index, step=step, observation=observation,
                                     typical_residual=typical), removal, corpus)
    return records


def attribute(session: Session, observation: np.ndarray, history: History, decision: Decision,
              record: dict) -> None:
    """Add to each supporting row of ``record`` its ``attribution``: SimplEx's Jacobian
    projection of the row on the decision's query belief
    (:func:`aoc_cli.belief.attribution.jacobian_projection`): ``projection`` (the row's belief
    shift projected on the query's), ``completeness_gap`` (the integration's error),
    ``observation`` (d_o,), ``action`` (d_a_in,) or None, ``history`` (L, F) or None; and to
    the record ``attribution_features`` (the features' names, a baseline note)."""
    rows = np.asarray(decision.support_rows, np.int64)
    if not len(rows):
        return
    model, corpus = session.model, session.corpus
    value = model.mode == "value"
    obs = np.asarray(observation, np.float32).reshape(1, -1)
    query = model.beliefs(obs, np.asarray(decision.action)[None] if value else None,
                          history)[0].astype(np.float64)
    order = np.sort(rows)  # h5py reads ascending rows
    res = jacobian_projection(model, query, corpus.read("observations", order),
                              corpus.read("actions", order) if value else None,
                              corpus.history(order, model.history_length))
    at = {int(r): i for i, r in enumerate(order)}
    for s in record["support"]:
        i = at[s["row"]]
        s["attribution"] = {
            "projection": float(res["projection"][i]),
            "completeness_gap": float(res["completeness_gap"][i]),
            **{k: None if res[k] is None else res[k][i].tolist()
               for k in ("observation", "action", "history")}}
    record["attribution_features"] = {
        **feature_names(model, corpus),
        "baseline": "the corpus's mean observation, no action, no history",
        "nodes": NODES}


def _query_history(history: History) -> dict:
    """The query's own previous steps (oldest first), as the record's ``query_history``:
    ``observations`` (L, d_o), ``actions`` (L, d_a) or (L,), ``present`` (L,) bool."""
    return {"observations": np.asarray(history.observations[0]).tolist(),
            "actions": np.asarray(history.actions[0]).tolist(),
            "present": np.asarray(history.mask[0], bool).tolist()}


def audit_band(session: Session, residuals: np.ndarray) -> np.ndarray:
    """(T,) the upper edge of the running OOD band over an episode's recorded residuals, as
    the rollout's monitor drew it with the session's settings (inf during the warm-up)."""
    cfg = session.controller.config
    floor, minimum = band_limits(session)
    monitor = OODMonitor(warmup=cfg.ood_warmup, sigmas=cfg.ood_sigmas, floor=floor,
                         minimum=minimum)
    for r in np.asarray(residuals, np.float64):
        monitor.update(float(r))
    return np.asarray(monitor.upper, np.float64)
