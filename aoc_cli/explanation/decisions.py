"""`aoc explain`'s library: the supporting rows, weights and residual behind decisions, from
each source a decision can come from, given a session (:mod:`aoc_cli.control.session`):

* :func:`explain_queries`: JSONL queries (:func:`parse_query`), each the controller's own
  decision (:func:`explain_query`), one given action, or several side by side;
* :func:`explain_logged_step`: a logged step of a corpus, the decision there and what supports
  the logged action;
* :func:`explain_recorded`: a decision an audit log recorded (:mod:`aoc_cli.control.audit`),
  replayed with its recorded inputs (:func:`replay_decision`).

Each turns its decisions into records with :func:`explain_decisions`: the decision record
(:func:`aoc_cli.control.decision_record`), the best action not chosen (``contrast``,
:mod:`aoc_cli.explanation.contrast`), each supporting row's attribution, and what changes without
some rows (``what_if``, :mod:`aoc_cli.explanation.whatif`).
"""

from __future__ import annotations

import json
import sys
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from aoc_cli.control.audit import read_audit_step, recorded_selection
from aoc_cli.control.config import ControllerConfig
from aoc_cli.control.controller import Decision
from aoc_cli.control.episodes import HistoryBuffer, check_same_spaces
from aoc_cli.control.monitor import OODMonitor, band_limits
from aoc_cli.control.records import decision_record, episode_ids, label_of
from aoc_cli.errors import AocError, param
from aoc_cli.explanation.attribution import NODES, feature_names, jacobian_projection
from aoc_cli.explanation.contrast import contrast_record
from aoc_cli.explanation.whatif import Removal, redecide, what_if_record
from aoc_cli.formats.impute import fill_query
from aoc_cli.store import History, action_labels

if TYPE_CHECKING:
    from aoc_cli.control.session import Session


# -- the sources -------------------------------------------------------------------------------
def explain_query(session: Session, observation, history, action=None,
                  compare: list | None = None,
                  selection: np.ndarray | None = None, removal=None,
                  measured: np.ndarray | None = None) -> list[dict]:
    """Records for a query: the controller's own choice (no action), one given action, or
    several actions side by side (``compare``); ``selection`` an (N,) bool row mask instead
    of the controller's own; ``removal`` (:func:`aoc_cli.explanation.whatif.removal`): each also
    re-decided without those rows (the record's ``what_if``); ``measured`` (d_o,) bool the
    observation's measured cells (None: all; rule 7 reads them)."""
    ctl = session.controller
    if compare:
        decisions = [ctl.decompose_candidates(observation, history,
                                              _as_candidates(session.corpus, [a]),
                                              choose=False, selection=selection)
                     for a in compare]
    elif action is not None:
        if session.model.mode == "imitation":
            raise AocError("an imitation-mode model explains its own decision; drop \"action\"")
        decisions = [ctl.decompose_candidates(observation, history,
                                              _as_candidates(session.corpus, [action]),
                                              choose=False, selection=selection)]
    else:
        decisions = [ctl.decide(observation, history, selection=selection, measured=measured)]
    return explain_decisions(session, observation, history, decisions, selection=selection,
                             removal=removal)


def explain_logged_step(session: Session, data, episode: int, step: int,
                        leave_episode_out: bool = True, removal=None) -> list[dict]:
    """What the controller decides at step ``step`` of episode ``episode`` of corpus ``data``
    (the session's own corpus, or held-out episodes of the same spaces), from that step's
    logged observation and history, and what supports the action that was logged there.
    When ``data`` is the session's corpus and ``leave_episode_out``, the episode's own rows
    are left out of the decompositions (else the logged action is explained by its own row).

    Returns [decision record (``logged_action`` added), the logged action's record] in value
    mode; the decision record alone in imitation mode (it explains only its own choice).
    ``removal``: as in :func:`explain_query`."""
    corpus = session.corpus
    same = data.hash == corpus.hash
    if not same:
        check_same_spaces(corpus, data, "explain its steps")
    if not 0 <= episode < data.n_episodes:
        raise AocError(f"corpus {data.name!r} has episodes 0..{data.n_episodes - 1}, "
                       f"not {episode}")
    start, end = (int(x) for x in data.episode_starts[episode:episode + 2])
    if not 0 <= step < end - start:
        raise AocError(f"episode {episode} of corpus {data.name!r} has steps "
                       f"0..{end - start - 1}, not {step}")
    row = start + step
    observation = np.asarray(data.read("observations", [row])[0], dtype=np.float64)
    history = data.history([row], session.history_length)
    logged = data.read("actions", [row])[0]
    logged = int(logged) if data.discrete else np.asarray(logged, dtype=np.float64).tolist()
    own = session.controller.selection
    selection = None
    if same and leave_episode_out:
        selection = np.ones(corpus.n_rows, bool) if own is None else own.copy()
        selection[start:end] = False
    gaps = data.imputed_mask                 # the step's filled cells are not measurements
    records = explain_query(session, observation, history, selection=selection,
                            removal=removal, measured=None if gaps is None else ~gaps[row])
    if session.model.mode == "value":
        records += explain_query(session, observation, history, action=logged,
                                 selection=selection, removal=removal)
    records[0]["logged_action"] = logged

    records[0].update(label_of(action_labels(corpus.action_space), logged,
                               "logged_action_label"))

    ids = episode_ids(data)
    for rec, role in zip(records, ("decision", "logged action")):
        rec.update({"role": role, "data": data.name, "episode": episode,
                    "episode_id": None if ids is None else ids[episode], "step": step,
                    "row": row, "episode_left_out": bool(same and leave_episode_out)})
    return records


def _as_candidates(corpus, actions: list) -> np.ndarray:
    if corpus.discrete:
        arr = np.asarray(actions, dtype=np.float64).reshape(-1)
        if np.any(arr != np.round(arr)) or np.any(arr < 0) or np.any(arr >= corpus.n_actions):
            raise AocError(f"discrete actions are integers in 0..{corpus.n_actions - 1}")
        return arr.astype(np.int64)
    arr = np.asarray(actions, dtype=np.float64)
    if arr.ndim == 1:
        arr = arr[:, None] if corpus.action_dim == 1 else arr[None]
    if arr.shape[1] != corpus.action_dim:
        raise AocError(f"an action of corpus {corpus.name!r} has {corpus.action_dim} "
                       f"numbers, got {arr.shape[1]}")
    return arr


def explain_queries(session: Session, source, compare: list | None = None,
                    removal: Removal | None = None) -> list[dict]:
    """JSONL queries (a file, or "-": stdin), one a line, each its own decision or the given
    actions compared (``compare``, or the query's own); each record carries its line
    (``query``)."""
    corpus = session.corpus
    lines = _read_lines(source)
    if not lines:
        raise AocError("the input holds no queries")
    records = []
    imputes = bool((getattr(corpus, "preprocessing", None) or {}).get("impute"))
    for lineno, line in lines:
        obs, hist, action, q_compare = parse_query(line, lineno, corpus,
                                                   session.model.history_length)
        nulls = null_cells(line, corpus, session.model.history_length) if imputes else None
        for rec in explain_query(session, obs, hist, action, compare=compare or q_compare,
                                 removal=removal,
                                 measured=None if nulls is None else ~np.asarray(nulls[0])):
            rec["query"] = lineno
            if imputes:  # which cells held null (the decision page marks them imputed)
                rec["query_imputed"], rec["query_history_imputed"] = nulls
            records.append(rec)
    return records


def null_cells(line: str, corpus, length: int) -> tuple[list, list]:
    """Which cells of a query (already parsed by :func:`parse_query`) held null and were
    filled by the corpus's imputation: the observation's (d_o,) and its history's (L, d_o),
    oldest first and padded at the front as the query's history is."""
    q = json.loads(line)
    d_o, d_a = corpus.observation_dim, corpus.action_dim

    def nulls(values) -> list[bool]:
        values = list(values)[:d_o]
        return [v is None for v in values] + [False] * (d_o - len(values))

    steps = [nulls(s[:len(s) - d_a - 1]) for s in q.get("history") or []][-length:] \
        if length else []
    return nulls(q["observation"]), [[False] * d_o] * (length - len(steps)) + steps


def explain_recorded(session: Session, recorded: dict, episode: int, step: int,
                     removal: Removal | None = None) -> list[dict]:
    """The record of a decision an audit log recorded (:func:`read_audit_step`'s
    ``recorded``), replayed with its recorded inputs by ``session`` (opened as
    :func:`recorded_session` says), with the recorded action beside it."""
    decision = replay_decision(session, recorded)
    rec, = explain_decisions(session, recorded["observation"], recorded["history"],
                             [decision], removal=removal, step=step)
    rec["episode"] = episode
    rec["recorded_action"] = recorded["action"].tolist()
    rec.update(label_of(action_labels(session.corpus.action_space), recorded["action"],
                        "recorded_action_label"))
    return [rec]


def recorded_session(corpus, audit, episode: int, step: int, config: ControllerConfig,
                     model_id: str | None, index_id: str) -> tuple[dict, dict]:
    """(the recorded decision, how to open its session): the step's inputs from the audit log
    (:func:`aoc_cli.control.audit.read_audit_step`) and ``dict(model_id, index_id, config,
    selection)`` as recorded (the given ``config``, ``model_id``, ``index_id`` where the log
    does not say)."""
    recorded = read_audit_step(audit, episode, step)
    meta = recorded["meta"]
    if meta.get("config"):
        config = ControllerConfig.from_dict(meta["config"], strict=False)
    return recorded, dict(model_id=meta.get("model", model_id),
                          index_id=meta.get("index", index_id), config=config,
                          selection=recorded_selection(recorded, corpus, audit))

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
    (:func:`aoc_cli.explanation.attribution.jacobian_projection`): ``projection`` (the row's belief
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


# -- replay and input ---------------------------------------------------------------------
def replay_decision(session: Session, recorded: dict) -> Decision:
    """Re-run a decision from an audit log with its recorded inputs (same candidates)."""
    meta = recorded["meta"]
    if meta.get("corpus_hash") != session.corpus.hash or \
            meta.get("model_hash") != session.model.hash:
        raise AocError("the audit log was recorded with another version of the corpus or "
                       "model: it cannot be replayed against this one")
    cand = recorded["candidates"]
    return session.controller.decide(recorded["observation"], recorded["history"],
                                     candidates=cand, measured=recorded.get("measured"))


def _numbers(value, what: str, nulls: bool = False) -> np.ndarray:
    """A JSON list of finite numbers -> (n,) float64 (``nulls``: ``null`` allowed, NaN);
    anything else is an AocError."""
    try:
        arr = np.asarray(value, dtype=np.float64).reshape(-1)
    except (TypeError, ValueError):
        raise AocError(f"{what} must be a list of numbers, got {json.dumps(value)[:60]}") \
            from None
    if nulls:
        if np.isinf(arr).any():
            raise AocError(f"{what} holds inf: give finite numbers (or null where unmeasured)")
        return arr
    if not np.isfinite(arr).all():
        raise AocError(f"{what} holds null, NaN or inf: give finite numbers (a corpus "
                       f"ingested with {param('impute')} takes null for an unmeasured value)")
    return arr


def _observation(value, what: str, corpus, previous=None) -> np.ndarray | None:
    """A query's observation, or None when its length is not the corpus's: with an imputed
    corpus ``null`` is allowed where unmeasured (filled by the corpus's rule and medians, never
    the query's own; its ``COL?measured`` features may be left out:
    :func:`aoc_cli.formats.impute.fill_query`)."""
    spec = corpus.preprocessing.get("impute") if hasattr(corpus, "preprocessing") else None
    obs = _numbers(value, what, nulls=spec is not None)
    if spec is not None and obs.shape[0] in (len(spec["names"]), corpus.observation_dim):
        obs = fill_query(obs[None, :], spec, previous)[0]
    return obs if obs.shape[0] == corpus.observation_dim else None


def parse_query(line: str, lineno: int, corpus, history_length: int):
    """One JSONL query -> (observation (d_o,), one-row History, action or None)."""
    try:
        q = json.loads(line)
    except json.JSONDecodeError as err:
        raise AocError(f"line {lineno} of the input is not valid JSON: {err.msg}") from None
    if not isinstance(q, dict) or "observation" not in q:
        raise AocError(f"line {lineno}: a query is an object with an \"observation\" list")
    d_a = corpus.action_dim
    buf = HistoryBuffer(history_length, corpus.observation_dim, d_a, corpus.discrete)
    width = corpus.observation_dim + d_a + 1
    history = q.get("history") or []
    if not isinstance(history, list):
        raise AocError(f"line {lineno}: \"history\" must be a list of steps "
                       "[observation..., action..., reward]")
    previous = None
    for j, step in enumerate(history):
        what = f"line {lineno}: history step {j}"
        step = step if isinstance(step, list) else _numbers(step, what)
        _numbers([0.0 if v is None else v for v in step], what)  # numbers or null
        o = _observation(step[:len(step) - d_a - 1], what, corpus, previous) \
            if len(step) > d_a + 1 else None
        if o is None:
            raise AocError(f"{what} has {len(step)} numbers, expected {width} (observation, "
                           "action, reward)")
        a, r = _numbers(step[len(step) - d_a - 1:-1], what), _numbers(step[-1:], what)
        buf.push(o, int(a[0]) if corpus.discrete else a, float(r[0]))
        previous = o
    obs = _observation(q["observation"], f"line {lineno}: \"observation\"", corpus, previous)
    if obs is None:
        raise AocError(f"line {lineno}: observation has {len(np.ravel(q['observation']))} "
                       f"numbers, corpus {corpus.name!r} has {corpus.observation_dim}")
    action = q.get("action")
    compare = q.get("compare")
    return obs.astype(np.float32), buf.history(), action, compare


def _read_lines(source) -> list[tuple[int, str]]:
    if str(source) == "-":
        text = sys.stdin.read()
    else:
        path = Path(source)
        if not path.is_file():
            raise AocError(f"no such input file: {source}")
        text = path.read_text()
    return [(i + 1, line) for i, line in enumerate(text.splitlines()) if line.strip()]
