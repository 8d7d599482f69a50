"""The API's explain entries, one per source of the decisions explained (the supporting rows,
weights and residual behind each; the library is :mod:`aoc_cli.explanation.decisions`):

* :func:`explain_queries`: JSONL queries;
* :func:`explain_recorded`: a decision an ``aoc rollout --audit`` log recorded;
* :func:`explain_logged`: a logged step of a corpus;
* :func:`explain_steps`: the overview page of an ``aoc evaluate --steps`` file.

:func:`explain` is ``aoc explain``'s: the one of them its source names.
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from pathlib import Path

from aoc_cli.api.common import StoreLike, controller_config, open_store
from aoc_cli.control import open_session
from aoc_cli.control.config import ControllerLike
from aoc_cli.errors import AocError, BadSetting, param
from aoc_cli.explanation.decisions import explain_logged_step
from aoc_cli.explanation.decisions import explain_queries as _explain_queries
from aoc_cli.explanation.decisions import explain_recorded as _explain_recorded
from aoc_cli.explanation.decisions import recorded_session
from aoc_cli.explanation.pages import check_html, steps_overview, write_html
from aoc_cli.explanation.whatif import removal as removal_of
from aoc_cli.report.decision_page import PageContext, decision_section
from aoc_cli.report.html import esc, fragment
from aoc_cli.store import DEFAULT_INDEX

PathLike = str | os.PathLike


@dataclass(repr=False)
class Explained:
    """One record per decision explained (action, value, residual, the minimal corpus subset
    with weights, warnings, the contrast, the what-if), and the HTML page written, if any.
    In a notebook it shows the decision page's body (``_repr_html_``); ``to_frame()`` is one
    row per supporting row of each record (pandas)."""

    corpus: str
    records: list[dict]
    html: Path | None = None
    #: The corpus itself and the one a logged step was read from (the page reads them).
    source_corpus: object = field(default=None, compare=False)
    data_corpus: object = field(default=None, compare=False)

    def __repr__(self) -> str:
        parts = []
        for rec in self.records[:3]:
            value = "" if rec.get("value") is None else f" value {rec['value']:.4g}"
            parts.append(f"{rec.get('role', 'decision')}: action {rec['action']}{value}, "
                         f"residual {rec['residual']:.3g}, {len(rec['support'])} rows")
        more = f"; +{len(self.records) - 3} more" if len(self.records) > 3 else ""
        page = f", html={str(self.html)!r}" if self.html is not None else ""
        return f"Explained({self.corpus!r}: {'; '.join(parts) or 'no records'}{more}{page})"

    def _repr_html_(self) -> str:
        if self.source_corpus is None or not self.records:
            return f"<pre>{esc(repr(self))}</pre>"
        ctx = PageContext(self.source_corpus, self.data_corpus)
        return fragment("".join(decision_section(rec, ctx, f"decision-{i}")
                                for i, rec in enumerate(self.records)))

    def to_frame(self):
        """One row per supporting row of each record: the record's index, role, action,
        value and residual beside the row's episode, step, action, value and weight."""
        import pandas as pd  # a notebook's library, imported only here

        rows = [{"record": i, "role": rec.get("role", "decision"),
                 "decision": rec["action"], "decision_value": rec.get("value"),
                 "residual": rec["residual"], "row": s["row"], "episode": s["episode"],
                 "episode_id": s.get("episode_id"), "step": s["step"], "action": s["action"],
                 "value": s.get("value"), "weight": s["weight"]}
                for i, rec in enumerate(self.records) for s in rec["support"]]
        return pd.DataFrame(rows)


def explain_queries(name: str, queries: PathLike, *, store: StoreLike = None,
                    compare: list | None = None, model: str | None = None,
                    index_id: str = DEFAULT_INDEX, controller: ControllerLike = None,
                    seed: int = 0, without: dict[str, list[str]] | None = None,
                    without_episodes: list[str] | None = None,
                    html: PathLike | None = None) -> Explained:
    """Explain the decisions of corpus ``name``'s controller on ``queries``: a JSONL file (or
    "-": stdin), one query a line (observation, history, optionally an action or actions to
    compare); ``compare``: actions (numbers, or lists for several dimensions) explained side
    by side for every query. ``controller``: its settings, as
    :func:`~aoc_cli.api.open_session` (over the settings saved with the model).
    ``without`` ({tag: [values]}) / ``without_episodes`` (ids or numbers): decide again
    without those rows and report what changes. ``html``: also write the decision page."""
    s, corpus, opened, removal = _opened(name, store, html, model, index_id, controller, seed,
                                         without, without_episodes)
    records = _explain_queries(open_session(corpus, **opened), queries, compare or [], removal)
    return _written(corpus, records, html)


def explain_recorded(name: str, audit: PathLike, episode: int = 0, step: int = 0, *,
                     store: StoreLike = None, model: str | None = None,
                     index_id: str = DEFAULT_INDEX, controller: ControllerLike = None,
                     seed: int = 0, without: dict[str, list[str]] | None = None,
                     without_episodes: list[str] | None = None,
                     html: PathLike | None = None) -> Explained:
    """Explain step ``step`` of episode ``episode`` of ``audit``, a log ``aoc rollout --audit``
    wrote: the decision replayed with its recorded inputs, rows and settings (``model``,
    ``index_id`` and ``controller`` where the log does not record them). ``html``: also the
    decision page, with the episode's overview. Other arguments as
    :func:`explain_queries`."""
    s, corpus, opened, removal = _opened(name, store, html, model, index_id, controller, seed,
                                         without, without_episodes)
    recorded, replay = recorded_session(corpus, Path(audit), episode, step, opened["config"],
                                        opened["model_id"], opened["index_id"])
    session = open_session(corpus, **replay, seed=seed)
    records = _explain_recorded(session, recorded, episode, step, removal)
    return _written(corpus, records, html, session=session, audit=audit, episode=episode,
                    step=step)


def explain_logged(name: str, data: str, episode: int = 0, step: int = 0, *,
                   store: StoreLike = None, model: str | None = None,
                   index_id: str = DEFAULT_INDEX, controller: ControllerLike = None,
                   seed: int = 0, without: dict[str, list[str]] | None = None,
                   without_episodes: list[str] | None = None,
                   html: PathLike | None = None) -> Explained:
    """Explain step ``step`` of episode ``episode`` of corpus ``data`` (``name`` itself, each
    episode then decided without its own rows, or held-out episodes of the same spaces): the
    controller's decision there and what supports the logged action. Other arguments as
    :func:`explain_queries`."""
    s, corpus, opened, removal = _opened(name, store, html, model, index_id, controller, seed,
                                         without, without_episodes)
    source = corpus if data == name else s.corpus(data)
    records = explain_logged_step(open_session(corpus, **opened), source, episode, step,
                                  removal=removal)
    return _written(corpus, records, html, source=source)


def explain_steps(name: str, steps_file: PathLike, html: PathLike, *, store: StoreLike = None,
                  model: str | None = None, index_id: str = DEFAULT_INDEX) -> Explained:
    """Write the overview page of ``steps_file`` (an ``aoc evaluate --steps`` file of corpus
    ``name``'s decisions) to ``html``, against the index's typical residual."""
    s = open_store(store)
    check_html(Path(html), s.root)
    corpus = s.corpus(name)
    steps_overview(corpus, Path(steps_file), Path(html), model, index_id)
    return Explained(corpus.name, [], Path(html))


def explain(name: str, *, store: StoreLike = None, queries: PathLike | None = None,
            audit: PathLike | None = None, data: str | None = None, episode: int = 0,
            step: int = 0, compare: list | None = None, model: str | None = None,
            index_id: str = DEFAULT_INDEX, controller: ControllerLike = None, seed: int = 0,
            without: dict[str, list[str]] | None = None,
            without_episodes: list[str] | None = None, html: PathLike | None = None,
            steps_file: PathLike | None = None) -> Explained:
    """``aoc explain``: the entry its one source names, ``queries``
    (:func:`explain_queries`), ``audit`` + ``episode`` + ``step`` (:func:`explain_recorded`),
    ``data`` + ``episode`` + ``step`` (:func:`explain_logged`), or ``steps_file`` with
    ``html`` and no other source (:func:`explain_steps`)."""
    if steps_file is not None:
        if html is None or any(x is not None for x in (queries, audit, data)):
            raise BadSetting("steps_file", str(steps_file),
                             f"{param('steps_file', 'FILE')} writes an overview page: give "
                             f"{param('html', 'FILE')} and none of {param('queries')}, "
                             f"{param('audit')}, {param('data')}")
        return explain_steps(name, steps_file, html, store=store, model=model,
                             index_id=index_id)
    if sum(x is not None for x in (queries, audit, data)) != 1:
        raise AocError(f"give one of {param('queries', 'FILE|-')} (JSONL queries), "
                       f"{param('audit', 'FILE')} {param('episode', 'E')} {param('step', 'T')} "
                       f"(a recorded decision) or {param('data', 'CORPUS')} "
                       f"{param('episode', 'E')} {param('step', 'T')} (a logged step)")
    shared = dict(store=store, model=model, index_id=index_id, controller=controller,
                  seed=seed, without=without, without_episodes=without_episodes, html=html)
    if queries is not None:
        return explain_queries(name, queries, compare=compare, **shared)
    if audit is not None:
        return explain_recorded(name, audit, episode, step, **shared)
    return explain_logged(name, data, episode, step, **shared)


def _opened(name, store, html, model, index_id, controller, seed, without, without_episodes):
    """(the store, the corpus, how to open its session, the rows removed or None), the page's
    path checked first."""
    s = open_store(store)
    if html is not None:
        check_html(Path(html), s.root)
    corpus = s.corpus(name)
    opened = dict(model_id=model, index_id=index_id,
                  config=controller_config(controller), seed=seed)
    return s, corpus, opened, removal_of(corpus, without, without_episodes)


def _written(corpus, records: list[dict], html, **page) -> Explained:
    """The records, and the decision page written where ``html`` says."""
    if html is not None:
        write_html(Path(html), records, corpus, **page)
    return Explained(corpus.name, records, None if html is None else Path(html), corpus,
                     page.get("source"))
