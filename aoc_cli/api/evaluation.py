"""The API's evaluate entry: decide every logged step of a corpus and score the decisions
against what was logged (:mod:`aoc_cli.evaluation.score`; the chunks on Ray:
:mod:`aoc_cli.evaluation.ray`), and optionally the cohort report (``html=``:
:mod:`aoc_cli.explanation.cohort`). The result is an :class:`Evaluation`: the summary (a dict,
as ``aoc evaluate -f json`` prints it) that also renders itself in a notebook."""

from __future__ import annotations

import json
import os
from pathlib import Path
from typing import Sequence

from aoc_cli.api.common import StoreLike, controller_config, open_store
from aoc_cli.control import open_session
from aoc_cli.control.config import ControllerLike
from aoc_cli.errors import AocError, BadSetting, param
from aoc_cli.evaluation.cohort import TOP, check_by
from aoc_cli.evaluation.ray import evaluate_on_ray
from aoc_cli.evaluation.score import score_log
from aoc_cli.evaluation.records import step_records
from aoc_cli.explanation.cohort import check_report, cohort_data, write_cohort_report
from aoc_cli.explanation.whatif import removal as removal_of
from aoc_cli.explanation.whatif import what_if_steps
from aoc_cli.ope.evaluate_block import OPESettings, parse_estimators
from aoc_cli.progress import Progress
from aoc_cli.report.cohort import body
from aoc_cli.report.html import fragment
from aoc_cli.store import DEFAULT_INDEX, atomic_path

PathLike = str | os.PathLike


class Evaluation(dict):
    """An evaluation: its summary (this dict, the keys ``aoc evaluate -f json`` prints), the
    per-step results ``steps`` (:class:`~aoc_cli.evaluation.step_scores.StepScores`), and
    ``report`` (the cohort report's path when one was written). In a notebook it shows the
    cohort report (``_repr_html_``); ``to_frame()`` is one row per step (pandas)."""

    def __init__(self, summary: dict, steps=None, session=None, data=None,
                 report: Path | None = None, by: str | None = None, top: int = TOP):
        super().__init__(summary)
        self.steps, self.report = steps, report
        self._session, self._data, self._by, self._top = session, data, by, top

    def __repr__(self) -> str:
        verdict = self.get("verdict") or (f"accuracy {self['accuracy']:.3f}"
                                          if self.get("accuracy") is not None else None)
        return (f"Evaluation({self.get('corpus')!r} on {self.get('data')!r}: "
                f"{self.get('mode')} mode, {self.get('steps')} steps"
                + (f"; {verdict}" if verdict else "") + ")")

    def cohort(self, by: str | None = None, top: int | None = None) -> dict:
        """The cohort report's data (:func:`aoc_cli.evaluation.cohort.cohort`)."""
        if self.steps is None or self._session is None:
            raise AocError("this evaluation kept no per-step results (run on Ray): "
                           "evaluate in one process for its report")
        return cohort_data(self._session, self._data, dict(self), self.steps,
                           by or self._by, self._top if top is None else top)

    def _repr_html_(self) -> str:
        return fragment(body(self.cohort(), linked=False))

    def to_frame(self):
        """One row per held-out step: episode, step, row, logged, decided, residual, and
        v_hat / target / decided_value (value mode) or the scores (discrete imitation)."""
        import pandas as pd  # a notebook's library, imported only here

        res = self.steps
        if res is None:
            raise AocError("this evaluation kept no per-step results (run on Ray): evaluate "
                           "in one process for its steps")
        cols = {"episode": res.episode, "step": res.step, "row": res.row,
                "logged": list(res.logged) if res.logged.ndim > 1 else res.logged,
                "decided": list(res.decided) if res.decided.ndim > 1 else res.decided,
                "residual": res.residual, "warning": res.warning}
        for name in ("v_hat", "target", "decided_value"):
            if getattr(res, name) is not None:
                cols[name] = getattr(res, name)
        if res.scores is not None:
            cols.update({f"score_{a}": res.scores[:, a] for a in range(res.scores.shape[1])})
        return pd.DataFrame(cols)


def evaluate(name: str, data: str, *, store: StoreLike = None,
             baselines: Sequence[str] = ("knn", "bc"),
             steps_file: PathLike | None = None, model: str | None = None,
             index_id: str = DEFAULT_INDEX, controller: ControllerLike = None,
             exact: bool | None = None, seed: int = 0, ope: str | None = None,
             propensity: str | None = None, ope_gamma: float = 1.0,
             fqe_steps: int | None = None, fqe_refits: int | None = None,
             fqe_processes: int | None = None, workers: int | None = None,
             ray_address: str | None = None, without: dict[str, list[str]] | None = None,
             without_episodes: list[str] | None = None, html: PathLike | None = None,
             pages: PathLike | None = None, by: str | None = None, top: int = TOP,
             progress: Progress | None = None) -> Evaluation:
    """Decide every logged step of corpus ``data`` (held-out episodes of the same spaces, or
    ``name`` itself: each episode decided without its own rows) with corpus ``name``'s
    controller (``controller``: its settings, as :func:`~aoc_cli.api.open_session`) and score the decisions:
    accuracy, AUC, calibration or value R^2, residuals, and ``baselines`` (knn, bc) on the
    same steps. ``exact``: search the index exactly (None: up to the small-log bound, IVF
    beyond). ``ope`` ("pdwis,wdr,fqe", "none"), ``propensity``, ``ope_gamma``, ``fqe_steps``,
    ``fqe_refits`` (the bootstrap refits behind FQE's interval), ``fqe_processes`` (the
    processes FQE trains in; None: the cores, at most 4): offline policy evaluation of the
    decisions. ``workers`` / ``ray_address``: chunks of episodes as Ray tasks.
    ``without`` / ``without_episodes``: decide again without those rows and report what
    changes (``summary["what_if"]``). ``steps_file``: one JSON record per step written there.
    ``html``: the cohort report written there, with the decision pages of its ``top`` steps
    in ``pages`` (default: ``<report>-pages`` beside it) and the agreement by ``by`` (a tag,
    an observation feature or a numeric column of ``data``).
    Returns an :class:`Evaluation`: the summary ``aoc evaluate`` prints (its
    ``ope_warnings``: what the OPE could not do), a dict."""
    s = open_store(store)
    _check_report(html, pages, s.root)
    settings = ope_settings(ope, propensity, ope_gamma, fqe_steps, fqe_refits, fqe_processes,
                            seed)
    corpus = s.corpus(name)
    held_out = corpus if data == name else s.corpus(data)
    config = controller_config(controller)
    if removal_of(corpus, without, without_episodes) is not None and \
            (workers is not None or ray_address is not None):
        raise BadSetting("without", without, f"{param('without')} runs in one process: drop "
                         f"{param('workers')} / {param('ray_address')}")
    session = open_session(corpus, model, index_id, config, seed=seed)
    if workers is None and ray_address is None:
        return evaluate_session(session, held_out, names=list(baselines), settings=settings,
                                seed=seed, exact=exact, without=without,
                                without_episodes=without_episodes, steps_file=steps_file,
                                html=html, pages=pages, by=by, top=top, progress=progress)
    if workers is not None and workers < 1:  # the chunks of episodes as Ray tasks
        raise BadSetting("workers", workers, f"{param('workers')} must be >= 1, got {workers}")
    if progress is not None:
        progress(0, held_out.n_rows, f"evaluate {name} on {data}")
    summary, res = evaluate_on_ray(s.root, name, data, session.model.id, index_id, config,
                                   list(baselines), seed=seed, exact=exact, workers=workers,
                                   address=ray_address, progress=progress, ope=settings)
    return _finish(session, held_out, summary, res, steps_file, html, pages, by, top)


def ope_settings(ope, propensity, ope_gamma, fqe_steps, fqe_refits, fqe_processes,
                 seed) -> OPESettings | None:
    """The OPE's settings given, or None (the default: every estimator the log allows)."""
    if any(v is not None for v in (ope, propensity, fqe_steps, fqe_refits, fqe_processes)) \
            or ope_gamma != 1.0:
        return OPESettings(parse_estimators(ope), gamma=ope_gamma, propensity=propensity,
                           fqe_steps=fqe_steps, seed=seed, fqe_processes=fqe_processes,
                           **({} if fqe_refits is None else {"fqe_refits": fqe_refits}))
    return None


def _check_report(html, pages, store_root) -> None:
    if html is not None:
        check_report(html, pages, store_root)
    elif pages is not None:
        raise BadSetting("pages", str(pages), f"{param('pages', 'DIR')} holds the decision "
                         f"pages of the cohort report: give {param('html', 'FILE')} too")


def evaluate_session(session, held_out, *, names: Sequence[str] = ("knn", "bc"),
                     settings: OPESettings | None = None, seed: int = 0,
                     exact: bool | None = None, without: dict[str, list[str]] | None = None,
                     without_episodes: list[str] | None = None,
                     steps_file: PathLike | None = None, html: PathLike | None = None,
                     pages: PathLike | None = None, by: str | None = None, top: int = TOP,
                     progress: Progress | None = None, store_root=None) -> Evaluation:
    """:func:`evaluate` with an open session (its model, index and controller) on held-out
    corpus ``held_out``, in this process (``Session.evaluate``); ``store_root``: the report's
    paths checked against it first."""
    if store_root is not None:
        _check_report(html, pages, store_root)
    corpus = session.corpus
    removal = removal_of(corpus, without, without_episodes)
    check_by(held_out, by)
    if progress is not None:
        progress(0, held_out.n_rows, f"evaluate {corpus.name} on {held_out.name}")
    summary, res = score_log(session, held_out, list(names), seed=seed, progress=progress,
                             exact=exact, ope=settings)
    if removal is not None:  # the same steps decided again without the rows
        if progress is not None:
            progress(0, held_out.n_rows, f"without {removal.label}")
        after_summary, after = score_log(session, held_out, [], seed=seed, progress=progress,
                                         exact=exact, selection=removal.keep(None),
                                         ope=OPESettings(estimators=()))
        summary["what_if"] = what_if_steps(res, after, removal, corpus, after_summary)
    return _finish(session, held_out, summary, res, steps_file, html, pages, by, top)


def _finish(session, held_out, summary, res, steps_file, html, pages, by, top) -> Evaluation:
    """The steps file and the cohort report written; the Evaluation."""
    if steps_file is not None:
        with atomic_path(steps_file, suffix=".jsonl") as tmp:
            with open(tmp, "w") as fh:
                for rec in step_records(session, held_out, res):
                    fh.write(json.dumps(rec) + "\n")
    report = None
    if html is not None:
        write_cohort_report(session, held_out, summary, res, html, pages, by, top)
        report = Path(html)
    return Evaluation(summary, res, session, held_out, report, by, top)
