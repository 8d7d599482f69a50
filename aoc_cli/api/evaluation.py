"""The API's evaluate entry: decide every logged step of a corpus and score the decisions
against what was logged (:mod:`aoc_cli.evaluation.score`; the chunks on Ray:
:mod:`aoc_cli.evaluation.ray`)."""

from __future__ import annotations

import json
import os
from typing import Sequence

from aoc_cli.api.common import StoreLike, controller_config, open_store
from aoc_cli.control import open_session
from aoc_cli.control.config import ControllerLike
from aoc_cli.errors import BadSetting, param
from aoc_cli.evaluation.ray import evaluate_on_ray
from aoc_cli.evaluation.score import score_log
from aoc_cli.evaluation.records import step_records
from aoc_cli.explanation.whatif import removal as removal_of
from aoc_cli.explanation.whatif import what_if_steps
from aoc_cli.ope.evaluate_block import OPESettings, parse_estimators
from aoc_cli.progress import Progress
from aoc_cli.store import DEFAULT_INDEX, atomic_path


def evaluate(name: str, data: str, *, store: StoreLike = None,
             baselines: Sequence[str] = ("knn", "bc"),
             steps_file: str | os.PathLike | None = None, model: str | None = None,
             index_id: str = DEFAULT_INDEX, controller: ControllerLike = None,
             exact: bool | None = None, seed: int = 0, ope: str | None = None,
             propensity: str | None = None, ope_gamma: float = 1.0,
             fqe_steps: int | None = None, fqe_refits: int | None = None,
             fqe_processes: int | None = None, workers: int | None = None,
             ray_address: str | None = None, without: dict[str, list[str]] | None = None,
             without_episodes: list[str] | None = None,
             progress: Progress | None = None) -> dict:
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
    Returns the summary ``aoc evaluate`` prints (its ``ope_warnings``: what the OPE could not
    do)."""
    names = list(baselines)
    settings = None
    if any(v is not None for v in (ope, propensity, fqe_steps, fqe_refits, fqe_processes)) \
            or ope_gamma != 1.0:
        settings = OPESettings(parse_estimators(ope), gamma=ope_gamma, propensity=propensity,
                               fqe_steps=fqe_steps, seed=seed, fqe_processes=fqe_processes,
                               **({} if fqe_refits is None else {"fqe_refits": fqe_refits}))
    s = open_store(store)
    corpus = s.corpus(name)
    held_out = corpus if data == name else s.corpus(data)
    config = controller_config(controller)
    removal = removal_of(corpus, without, without_episodes)
    if removal is not None and (workers is not None or ray_address is not None):
        raise BadSetting("without", without, f"{param('without')} runs in one process: drop "
                         f"{param('workers')} / {param('ray_address')}")
    session = open_session(corpus, model, index_id, config, seed=seed)
    if progress is not None:
        progress(0, held_out.n_rows, f"evaluate {name} on {data}")
    if workers is None and ray_address is None:
        summary, res = score_log(session, held_out, names, seed=seed, progress=progress,
                                 exact=exact, ope=settings)
    else:  # the chunks of episodes as Ray tasks (aoc_cli.evaluation.ray)
        if workers is not None and workers < 1:
            raise BadSetting("workers", workers, f"{param('workers')} must be >= 1, got {workers}")
        summary, res = evaluate_on_ray(s.root, name, data, session.model.id, index_id, config,
                                       names, seed=seed, exact=exact, workers=workers,
                                       address=ray_address, progress=progress, ope=settings)
    if removal is not None:  # the same steps decided again without the rows
        if progress is not None:
            progress(0, held_out.n_rows, f"without {removal.label}")
        after_summary, after = score_log(session, held_out, [], seed=seed, progress=progress,
                                         exact=exact, selection=removal.keep(None),
                                         ope=OPESettings(estimators=()))
        summary["what_if"] = what_if_steps(res, after, removal, corpus, after_summary)
    if steps_file is not None:
        with atomic_path(steps_file, suffix=".jsonl") as tmp:
            with open(tmp, "w") as fh:
                for rec in step_records(session, held_out, res):
                    fh.write(json.dumps(rec) + "\n")
    return summary
