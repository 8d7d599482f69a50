"""The library entry points behind `aoc rollout` and `aoc explain`, given a session
(:mod:`aoc_cli.control.session`)."""

from __future__ import annotations

import json
import sys
from typing import TYPE_CHECKING

import numpy as np

from aoc_cli.control.config import ControllerConfig
from aoc_cli.formats.impute import fill_query
from aoc_cli.control.controller import Decision
from aoc_cli.control.monitor import OODMonitor, band_limits, reference_band
from aoc_cli.control.records import (decision_record, episode_ids, label_of, read_audit_residuals,
                                     write_audit)
from aoc_cli.control.episodes import (EpisodeResult, HistoryBuffer, Policy, check_same_spaces,
                                     check_spaces, run_episode, summarize)
from aoc_cli.errors import AocError, BadInput, call, param
from aoc_cli.progress import Progress
from aoc_cli.store import action_labels
from aoc_cli.threads import thread_limits

if TYPE_CHECKING:
    from aoc_cli.control.session import ModelFreeSession, Session


def rollout(session: Session | ModelFreeSession, env, episodes: int, seed: int = 0,
            policy: Policy | None = None,
            audit: str | None = None, noise_after: int | None = None, noise_std: float = 0.0,
            progress: Progress | None = None, reference=None
            ) -> tuple[list[EpisodeResult], dict]:
    """Run ``episodes`` episodes (seeds ``seed``, ``seed+1``, ...) with the controller (or
    another ``policy`` with a ``decide(observation, history)`` method). ``reference``: a (T,)
    band from :func:`aoc_cli.control.monitor.reference_band` for the OOD monitor, instead of
    the running band of each episode's own steps. ``progress``: episodes done
    (:mod:`aoc_cli.progress`). The steps run with one thread in torch, FAISS and BLAS."""
    check_spaces(env, session.corpus)
    controller = getattr(session, "controller", None)
    policy = policy or controller
    if policy is None:
        raise AocError("a model-free session runs only a given policy (zero or random)")
    cfg = controller.config if controller is not None else None
    floor, minimum = band_limits(session)
    results = []
    if progress is not None:
        progress(0, episodes, "rollout")
    # every policy's steps with one thread in each pool, as the controller's own
    # (aoc_cli.threads; torch's only when a policy has loaded it)
    with thread_limits(torch=1 if "torch" in sys.modules else None, faiss=1, blas=1):
        for e in range(episodes):
            monitor = None if cfg is None else OODMonitor(
                warmup=cfg.ood_warmup, sigmas=cfg.ood_sigmas, floor=floor, minimum=minimum,
                reference=reference)
            res = run_episode(env, policy, session.history_length, session.corpus, e,
                              seed + e, monitor, noise_after, noise_std,
                              keep_decisions=audit is not None)
            results.append(res)
            if progress is not None:
                progress(e + 1, episodes, f"rollout (return {res.total_return:.1f})")
    if audit is not None:
        write_audit(audit, results, session.meta(), corpus=session.corpus,
                    selection=None if controller is None else controller.selection)
    return results, summarize(results)


def explain_query(session: Session, observation, history, action=None,
                  compare: list | None = None,
                  selection: np.ndarray | None = None, removal=None) -> list[dict]:
    """Records for a query: the controller's own choice (no action), one given action, or
    several actions side by side (``compare``); ``selection`` an (N,) bool row mask instead
    of the controller's own; ``removal`` (:func:`aoc_cli.control.whatif.removal`): each also
    re-decided without those rows (the record's ``what_if``)."""
    # lazy: torch (explain's attributions); importing aoc_cli.control must not load it
    from aoc_cli.control.explain import explain_decisions

    ctl = session.controller
    if compare:
        decisions = [ctl.evaluate(observation, history, _as_candidates(session.corpus, [a]),
                                  choose=False, selection=selection) for a in compare]
    elif action is not None:
        if session.model.mode == "imitation":
            raise AocError("an imitation-mode model explains its own decision; drop \"action\"")
        decisions = [ctl.evaluate(observation, history,
                                  _as_candidates(session.corpus, [action]), choose=False,
                                  selection=selection)]
    else:
        decisions = [ctl.decide(observation, history, selection=selection)]
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
    records = explain_query(session, observation, history, selection=selection,
                            removal=removal)
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


def reference_from_audit(session: Session, path) -> np.ndarray:
    """(T,) OOD reference band from the residuals of a clean rollout's audit log, recorded
    with this session's corpus and model (:func:`aoc_cli.control.monitor.reference_band`)."""
    meta, runs = read_audit_residuals(path)
    if meta.get("corpus_hash") != session.corpus.hash or \
            meta.get("model_hash") != session.model.hash:
        raise BadInput(path, f"the audit log {path} was recorded with another version of the "
                       "corpus or model: record the clean reference again with "
                       f"`{call('rollout', session.corpus.name, '...', audit='FILE')}`")
    return session_reference_band(session, runs)


def session_reference_band(session: Session, runs) -> np.ndarray:
    """(T,) reference band from clean runs' per-step residuals, with the session's sigmas and
    the same floor and minimum (the corpus's typical p50 / p99 residual) as its running band."""
    floor, minimum = band_limits(session)
    return reference_band(runs, sigmas=session.controller.config.ood_sigmas, floor=floor,
                          minimum=minimum)


def replay_decision(session: Session, recorded: dict) -> Decision:
    """Re-run a decision from an audit log with its recorded inputs (same candidates)."""
    meta = recorded["meta"]
    if meta.get("corpus_hash") != session.corpus.hash or \
            meta.get("model_hash") != session.model.hash:
        raise AocError("the audit log was recorded with another version of the corpus or "
                       "model: it cannot be replayed against this one")
    cand = recorded["candidates"]
    return session.controller.decide(recorded["observation"], recorded["history"],
                                     candidates=cand)


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
