"""The library entry point behind `aoc rollout`, given a session
(:mod:`aoc_cli.control.session`): episodes run with the controller (or another policy), the
OOD monitor's reference band, the audit log written (:mod:`aoc_cli.control.audit`)."""

from __future__ import annotations

import sys
from typing import TYPE_CHECKING

import numpy as np

from aoc_cli.control.audit import read_audit_residuals, write_audit
from aoc_cli.control.episodes import EpisodeResult, Policy, check_spaces, run_episode, summarize
from aoc_cli.control.monitor import OODMonitor, band_limits, reference_band
from aoc_cli.errors import AocError, BadInput, call
from aoc_cli.progress import Progress
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
