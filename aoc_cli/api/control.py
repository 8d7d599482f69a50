"""The API's entries that decide: open_session (a controller ready to act) and rollout (the
controller, or a baseline, run in an environment)."""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

from aoc_cli.api.common import StoreLike, controller_config, open_store
from aoc_cli.baselines import make_baseline
from aoc_cli.api.session import Session
from aoc_cli.control import EpisodeResult, model_free_session, rollout as _rollout
from aoc_cli.control.config import ControllerLike
from aoc_cli.control import open_session as _open_session
from aoc_cli.control.episodes import action_space_of
from aoc_cli.control.run import reference_from_audit
from aoc_cli.envs import make_env
from aoc_cli.errors import BadSetting, param
from aoc_cli.progress import Progress
from aoc_cli.rows import row_selection
from aoc_cli.store import DEFAULT_INDEX
from aoc_cli.store.paths import check_output

#: Policies that need no model or index: they run on a corpus before anything is trained.
MODEL_FREE = ("zero", "random")


def open_session(name: str, *, store: StoreLike = None, model: str | None = None,
                 index_id: str = DEFAULT_INDEX, env: str | None = None, seed: int = 0,
                 select: dict[str, list[str]] | None = None,
                 exclude: dict[str, list[str]] | None = None,
                 controller: ControllerLike = None) -> Session:
    """A controller ready to act on corpus ``name``: its model ``model`` (default 'default',
    else the latest), index ``index_id``, the rows of the tag selections ``select`` /
    ``exclude`` ({tag: [values]}), and the controller settings ``controller`` (a
    ControllerConfig, taken whole, or a mapping of its fields, e.g. ``{"epsilon": 0.1}``; a
    setting not given, or None: the model's, decided by ``aoc train`` from the log's
    evidence, else the paper's). ``env``: a built-in task or gymnasium id whose action box
    applies (default: the corpus's).
    ``session.controller.decide(observation (d_o,), history (L, d_o + d_a + 1))`` -> a
    Decision (action, value, residual, supporting rows and weights); ``session.explain(...)``
    and ``session.evaluate(...)`` reuse the model and index it has loaded
    (:class:`aoc_cli.api.session.Session`)."""
    s = open_store(store)
    corpus = s.corpus(name)
    config = controller_config(controller)
    action_space = action_space_of(make_env(env)) if env is not None else None
    return Session.of(_open_session(corpus, model, index_id, config,
                                    row_selection(corpus, select, exclude), seed,
                                    action_space), s)


@dataclass
class RolledOut:
    """Episodes run: one :class:`~aoc_cli.control.EpisodeResult` each (``.summary()`` a row)
    and the summary over them (mean return, success, OOD flags, residuals)."""

    corpus: str
    env: str
    policy: str
    results: list[EpisodeResult]
    summary: dict


def rollout(name: str, env: str, *, store: StoreLike = None, episodes: int = 5,
            policy: str = "aoc", model: str | None = None, index_id: str = DEFAULT_INDEX,
            controller: ControllerLike = None, select: dict[str, list[str]] | None = None,
            exclude: dict[str, list[str]] | None = None, seed: int = 0,
            audit: str | os.PathLike | None = None, plot: str | os.PathLike | None = None,
            noise_after: int | None = None, noise_std: float = 0.5,
            ood_reference: str | os.PathLike | None = None,
            progress: Progress | None = None) -> RolledOut:
    """Run ``episodes`` episodes of ``env`` (a built-in task or a gymnasium id) with
    ``policy`` (aoc, or a baseline: zero, random, 1nn, knn, bc, td3bc, cql, mpc, ...) acting
    on corpus ``name``; episode i starts from seed ``seed + i``. ``controller``: the controller
    settings given (as :func:`open_session`), over the model's own. ``audit``: write every decision to
    this HDF5 file; ``plot``: a PNG of the trajectories or the residual/reward curves;
    ``noise_after``, ``noise_std``: disturb the actions after that step (a fraction of the
    action range); ``ood_reference``: flag steps against the per-step band of this audit log
    of clean rollouts."""
    s = open_store(store)
    if episodes < 1:
        raise BadSetting("episodes", episodes, f"{param('episodes')} must be >= 1, got {episodes}")
    for key, path in (("audit", audit), ("plot", plot)):
        if path is not None:
            check_output(path, key, s.root)
    if noise_std != noise_std or noise_std < 0 or noise_std == float("inf"):
        raise BadSetting("noise_std", noise_std, f"{param('noise_std')} must be a finite number "
                         f">= 0, got {noise_std}")
    corpus = s.corpus(name)
    config = controller_config(controller)
    environment = make_env(env)
    selection = row_selection(corpus, select, exclude)
    action_space = action_space_of(environment)
    if policy in MODEL_FREE:
        session = model_free_session(corpus, action_space)
    else:
        session = _open_session(corpus, model, index_id, config, selection, seed, action_space)
    baseline = None if policy == "aoc" else make_baseline(policy, session, environment,
                                                           seed=seed)
    reference = None
    if ood_reference is not None:
        if policy in MODEL_FREE:
            raise BadSetting("ood_reference", str(ood_reference),
                             f"{param('ood_reference')} needs the AOC controller's residuals; "
                             f"{param('policy', policy)} has none")
        reference = reference_from_audit(session, ood_reference)
    results, summary = _rollout(session, environment, episodes, seed=seed, policy=baseline,
                                audit=str(audit) if audit else None, noise_after=noise_after,
                                noise_std=noise_std, progress=progress, reference=reference)
    if plot is not None:
        _plot(env, results, Path(plot), noise_after)
    return RolledOut(corpus.name, env, policy, results, summary)


def _plot(env: str, results: list[EpisodeResult], path: Path, noise_after) -> None:
    from aoc_cli.report.plots import plot_rollouts  # lazy: matplotlib, for --plot only

    plot_rollouts(env, results, path, noise_after)
