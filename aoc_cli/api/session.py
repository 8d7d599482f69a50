"""The notebook's session: :func:`aoc_cli.open_session`'s result, a controller ready to act
(:class:`aoc_cli.control.Session`) that also explains and evaluates with the model, index and
controller it has loaded, instead of opening them again on every call.

>>> session = aoc_cli.open_session("icu-train", store="corpora")      # doctest: +SKIP
>>> session.explain(data="icu-test", episode=3, step=2)                # doctest: +SKIP
>>> session.evaluate("icu-test", html="report.html")                   # doctest: +SKIP
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path
from typing import Sequence

import numpy as np

from aoc_cli.api.evaluation import Evaluation, evaluate_session, ope_settings
from aoc_cli.api.explanation import Explained
from aoc_cli.control import Decision, Session as ControlSession
from aoc_cli.control.episodes import HistoryBuffer
from aoc_cli.errors import AocError, param
from aoc_cli.evaluation.cohort import TOP
from aoc_cli.explanation.decisions import explain_logged_step, explain_query
from aoc_cli.explanation.pages import check_html, write_html
from aoc_cli.explanation.whatif import removal as removal_of
from aoc_cli.progress import Progress
from aoc_cli.store import History

PathLike = str | os.PathLike

__all__ = ["Decision", "Session"]


@dataclass(repr=False)
class Session(ControlSession):
    """A controller ready to act (``.controller.decide(observation, history)``), and
    :meth:`explain` and :meth:`evaluate` on what it has loaded. ``store``: the store its
    corpus came from (held-out corpora are read from it by name)."""

    store: object = None

    @classmethod
    def of(cls, session: ControlSession, store=None) -> Session:
        """The notebook's session over an opened one (nothing is loaded again)."""
        return cls(session.corpus, session.model, session.index, session.controller,
                   session.action_space, store)

    def __repr__(self) -> str:
        return (f"Session(corpus={self.corpus.name!r}, model={self.model.id!r}, "
                f"mode={self.model.mode!r}, index={self.index.index_id!r}, "
                f"rows={self.corpus.n_rows})")

    def _root(self) -> Path:
        """The store's folder (the corpus's own parent when the session knows no store)."""
        return Path(self.store.root) if self.store is not None else self.corpus.path.parent

    def _corpus(self, data):
        if data is None or data == self.corpus.name:
            return self.corpus
        if not isinstance(data, str):
            return data                                    # a Corpus already open
        if self.store is None:
            raise AocError("this session knows no store: give the held-out corpus itself")
        return self.store.corpus(data)

    def explain(self, data=None, episode: int = 0, step: int = 0, *, observation=None,
                history=None, action=None, compare: list | None = None,
                without: dict[str, list[str]] | None = None,
                without_episodes: list[str] | None = None,
                html: PathLike | None = None) -> Explained:
        """Explain a decision with this session's model and index: step ``step`` of episode
        ``episode`` of corpus ``data`` (a name in the session's store or a Corpus; the
        session's own corpus, each episode decided without its own rows, when None), or the
        query ``observation`` (d_o,) with ``history`` (a History, or a list of (observation,
        action, reward) steps, oldest first; None: no past); ``action`` / ``compare``: an
        action, or several, explained instead of the controller's choice (value mode).
        ``without`` / ``without_episodes``: decide again without those rows. ``html``: also
        write the decision page. An :class:`~aoc_cli.api.explanation.Explained`."""
        if html is not None:
            check_html(Path(html), self._root())
        removal = removal_of(self.corpus, without, without_episodes)
        source = None
        if observation is not None:
            if data is not None:
                raise AocError(f"give {param('data')} (a logged step) or "
                               f"{param('observation')} (a query), not both")
            records = explain_query(self, np.asarray(observation, np.float32),
                                    self._history(history), action=action, compare=compare,
                                    removal=removal)
        else:
            source = self._corpus(data)
            records = explain_logged_step(self, source, episode, step, removal=removal)
        if html is not None:
            write_html(Path(html), records, self.corpus, source=source)
        return Explained(self.corpus.name, records, None if html is None else Path(html),
                         self.corpus, source)

    def _history(self, history) -> History:
        if isinstance(history, History):
            return history
        corpus = self.corpus
        buf = HistoryBuffer(self.history_length, corpus.observation_dim, corpus.action_dim,
                            corpus.discrete)
        for o, a, r in history or []:
            buf.push(o, a, r)
        return buf.history()

    def evaluate(self, data, *, baselines: Sequence[str] = ("knn", "bc"),
                 exact: bool | None = None, seed: int = 0, ope: str | None = None,
                 propensity: str | None = None, ope_gamma: float = 1.0,
                 fqe_steps: int | None = None, fqe_refits: int | None = None,
                 fqe_processes: int | None = None,
                 without: dict[str, list[str]] | None = None,
                 without_episodes: list[str] | None = None,
                 steps_file: PathLike | None = None, html: PathLike | None = None,
                 pages: PathLike | None = None, by: str | None = None, top: int = TOP,
                 progress: Progress | None = None) -> Evaluation:
        """Decide and score every logged step of corpus ``data`` (a name in the session's
        store, or a Corpus) with this session, as :func:`aoc_cli.evaluate` does (the same
        arguments; in this process). An :class:`~aoc_cli.api.evaluation.Evaluation`: the
        summary, shown in a notebook as the cohort report."""
        held_out = self._corpus(data)
        settings = ope_settings(ope, propensity, ope_gamma, fqe_steps, fqe_refits,
                                fqe_processes, seed)
        return evaluate_session(self, held_out, names=list(baselines), settings=settings,
                                seed=seed, exact=exact, without=without,
                                without_episodes=without_episodes, steps_file=steps_file,
                                html=html, pages=pages, by=by, top=top, progress=progress,
                                store_root=self._root())
