"""The API's explain entry: the supporting rows, weights and residual behind decisions, from
JSONL queries, a recorded step of an audit log, or a logged step of a corpus; optionally the
decision page (HTML)."""

from __future__ import annotations

import json
import os
import sys
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from aoc_cli.api.common import StoreLike, controller_config, open_store
from aoc_cli.envs import collected_task
from aoc_cli.control import (ControllerConfig, explain_logged_step, explain_query, open_session,
                             parse_query, read_audit_step, replay_decision)
from aoc_cli.control.config import ControllerLike
from aoc_cli.control.explain import explain_decisions
from aoc_cli.control.records import label_of
from aoc_cli.control.whatif import removal as removal_of
from aoc_cli.errors import AocError, BadSetting, call, param
from aoc_cli.report.explain_pages import check_html, steps_overview, write_html
from aoc_cli.store import DEFAULT_INDEX, action_labels


@dataclass
class Explained:
    """One record per decision explained (action, value, residual, the minimal corpus subset
    with weights, warnings, the contrast, the what-if), and the HTML page written, if any."""

    corpus: str
    records: list[dict]
    html: Path | None = None


def explain(name: str, *, store: StoreLike = None, queries: str | os.PathLike | None = None,
            audit: str | os.PathLike | None = None, data: str | None = None,
            episode: int = 0, step: int = 0, compare: list | None = None,
            model: str | None = None, index_id: str = DEFAULT_INDEX,
            controller: ControllerLike = None, seed: int = 0,
            without: dict[str, list[str]] | None = None,
            without_episodes: list[str] | None = None, html: str | os.PathLike | None = None,
            steps_file: str | os.PathLike | None = None) -> Explained:
    """Explain decisions of corpus ``name``'s controller, from one source:

    * ``queries``: a JSONL file (or "-": stdin), one query a line (observation, history,
      optionally an action or actions to compare); ``compare``: actions (numbers, or lists
      for several dimensions) explained side by side for every query;
    * ``audit`` + ``episode`` + ``step``: a decision an ``aoc rollout --audit`` log recorded,
      replayed with its recorded inputs and settings;
    * ``data`` + ``episode`` + ``step``: the decision at a logged step of corpus ``data``
      (``name`` itself or held-out episodes) and what supports the logged action there.

    ``controller``: the controller settings, as :func:`~aoc_cli.api.open_session` (over the
    settings of the task the corpus was collected from; a recorded decision is replayed with
    its recorded settings). ``without`` ({tag: [values]}) / ``without_episodes`` (ids or numbers):
    decide again without those rows and report what changes. ``html``: also write the
    decision page; with ``steps_file`` (an ``aoc evaluate --steps`` file) and no source,
    write that file's overview page only."""
    s = open_store(store)
    if html is not None:
        check_html(Path(html), s.root)
    if steps_file is not None:
        if html is None or any(x is not None for x in (queries, audit, data)):
            raise BadSetting("steps_file", str(steps_file),
                             f"{param('steps_file', 'FILE')} writes an overview page: give "
                             f"{param('html', 'FILE')} and none of {param('queries')}, "
                             f"{param('audit')}, {param('data')}")
        corpus = s.corpus(name)
        steps_overview(corpus, Path(steps_file), Path(html), model, index_id)
        return Explained(corpus.name, [], Path(html))
    if sum(x is not None for x in (queries, audit, data)) != 1:
        raise AocError(f"give one of {param('queries', 'FILE|-')} (JSONL queries), "
                       f"{param('audit', 'FILE')} {param('episode', 'E')} {param('step', 'T')} "
                       f"(a recorded decision) or {param('data', 'CORPUS')} "
                       f"{param('episode', 'E')} {param('step', 'T')} (a logged step)")
    corpus = s.corpus(name)
    config = controller_config(controller, collected_task(corpus))
    opened = dict(model_id=model, index_id=index_id, config=config, seed=seed)
    removal = removal_of(corpus, without, without_episodes)
    session = source = None
    if data is not None:
        source = corpus if data == name else s.corpus(data)
        records = explain_logged_step(open_session(corpus, **opened), source, episode, step,
                                      removal=removal)
    elif audit is not None:
        records, session = _recorded_step(corpus, Path(audit), episode, step, opened, removal)
    else:
        records = _queries(open_session(corpus, **opened), queries, compare or [], removal)
    if html is not None:
        write_html(Path(html), records, corpus, session=session, audit=audit,
                   episode=episode, step=step, source=source)
    return Explained(corpus.name, records, None if html is None else Path(html))


def _recorded_step(corpus, audit: Path, episode: int, step: int, opened: dict,
                   removal) -> tuple[list[dict], object]:
    """``audit``: a recorded decision replayed with its recorded inputs and settings;
    (records, the session)."""
    recorded = read_audit_step(audit, episode, step)
    meta = recorded["meta"]
    config = ControllerConfig.from_dict(meta["config"], strict=False) if meta.get("config") \
        else opened["config"]
    session = open_session(corpus, meta.get("model", opened["model_id"]),
                           meta.get("index", opened["index_id"]), config,
                           selection=_recorded_selection(recorded["selection"], corpus, audit),
                           seed=opened["seed"])
    decision = replay_decision(session, recorded)
    rec, = explain_decisions(session, recorded["observation"], recorded["history"],
                             [decision], removal=removal, step=step)
    rec["episode"] = episode
    rec["recorded_action"] = recorded["action"].tolist()
    rec.update(label_of(action_labels(corpus.action_space), recorded["action"],
                        "recorded_action_label"))
    return [rec], session


def _recorded_selection(kept, corpus, audit: Path) -> np.ndarray | None:
    """The (N,) row mask a recorded decision was made from (``read_audit_step``'s
    ``selection``), or None for every row; an AocError where the log cannot say."""
    if kept is None:
        return None
    if isinstance(kept, str):
        raise AocError(f"audit log {audit} was recorded from a selection of the corpus rows "
                       f"that it does not hold (written by an older aoc): record it again "
                       f"with `{call('rollout', '...', audit='FILE')}`")
    if isinstance(kept, list):                  # rows listed by an older aoc
        rows = np.asarray(kept, np.int64)
        kept = np.zeros(max(corpus.n_rows, int(rows.max(initial=-1)) + 1), bool)
        kept[rows] = True
    if len(kept) != corpus.n_rows:
        raise AocError(f"audit log {audit} was recorded from a corpus of {len(kept)} rows, "
                       f"{corpus.name!r} has {corpus.n_rows}: it cannot be replayed against it")
    return kept


def _queries(session, source, compare: list, removal) -> list[dict]:
    """JSONL queries, each its own decision or the given actions compared."""
    corpus = session.corpus
    lines = _read_lines(source)
    if not lines:
        raise AocError("the input holds no queries")
    records = []
    imputes = bool((getattr(corpus, "preprocessing", None) or {}).get("impute"))
    for lineno, line in lines:
        obs, hist, action, q_compare = parse_query(line, lineno, corpus,
                                                   session.model.history_length)
        for rec in explain_query(session, obs, hist, action, compare=compare or q_compare,
                                 removal=removal):
            rec["query"] = lineno
            if imputes:
                rec["query_imputed"], rec["query_history_imputed"] = _null_cells(
                    line, corpus, session.model.history_length)
            records.append(rec)
    return records


def _null_cells(line: str, corpus, length: int) -> tuple[list, list]:
    """Which cells of a query (parsed already) held null and were filled by the corpus's
    imputation: the observation's (d_o,) and its history's (L, d_o), oldest first and padded
    at the front as the query's history is (the decision page marks them)."""
    q = json.loads(line)
    d_o, d_a = corpus.observation_dim, corpus.action_dim

    def nulls(values) -> list[bool]:
        values = list(values)[:d_o]
        return [v is None for v in values] + [False] * (d_o - len(values))

    steps = [nulls(s[:len(s) - d_a - 1]) for s in q.get("history") or []][-length:] \
        if length else []
    return nulls(q["observation"]), [[False] * d_o] * (length - len(steps)) + steps


def _read_lines(source) -> list[tuple[int, str]]:
    if str(source) == "-":
        text = sys.stdin.read()
    else:
        path = Path(source)
        if not path.is_file():
            raise AocError(f"no such input file: {source}")
        text = path.read_text()
    return [(i + 1, line) for i, line in enumerate(text.splitlines()) if line.strip()]
