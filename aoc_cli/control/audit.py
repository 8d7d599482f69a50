"""The audit log: every decision of a rollout in one HDF5 file, written atomically. This
module is the only reader and writer of its format.

The file's attribute ``meta`` (JSON: corpus, hashes, model, index, controller config), an
optional dataset ``selection`` (the corpus rows decided from: packed bits, attribute ``rows``)
and one group ``episode_<e>`` per episode (attributes seed, return, length, success) holding,
per step t < T: ``observations`` (T, d_o), ``rewards``, ``ood``, the history
(``history_observations``, ``history_actions``, ``history_rewards``, ``history_mask``), and
where a controller decided: ``support_rows`` / ``support_weights`` / ``support_distances`` (T,
m; -1 / 0 / NaN padded), ``support_episode_ids``, ``actions``, ``values``, ``residuals``,
``candidates`` (T, K[, d_a]) and ``warnings`` (JSON); ``measured`` (T, d_o) bool where the
environment said which cells it measured (rule 7 reads them). The inputs of each decision are
kept, so any recorded decision can be re-run and explained again (:func:`read_audit_step`).
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import h5py
import numpy as np

from aoc_cli.control.records import episode_ids
from aoc_cli.errors import AocError, BadInput, call
from aoc_cli.store import History, atomic_path


def write_audit(path, episodes: list, meta: dict, corpus=None,
                selection: np.ndarray | None = None) -> None:
    """Every decision of every episode in one HDF5 file (atomically).

    ``episodes`` is a list of :class:`aoc_cli.control.episodes.EpisodeResult` run with
    ``keep_decisions=True``; ``meta`` (corpus, hashes, controller config...) goes in the
    file's attributes as JSON.
    With ``corpus``, each step's supporting rows also carry their episodes' own ids
    (``support_episode_ids``, "" where padded) when the corpus has them.
    ``selection``: the (N,) bool mask of the corpus rows the controller decided from (``--select``
    / ``--exclude``), kept as dataset ``selection`` (packed bits, attribute ``rows`` N) so that
    a replay decides from the same rows (:func:`read_audit_step`).
    """
    with atomic_path(path, suffix=".h5") as tmp:
        with h5py.File(tmp, "w") as f:
            f.attrs["meta"] = json.dumps(meta)
            if selection is not None:
                mask = np.asarray(selection, bool)
                f["selection"] = np.packbits(mask)
                f["selection"].attrs["rows"] = len(mask)
            for ep in episodes:
                g = f.create_group(f"episode_{ep.episode}")
                g.attrs["seed"] = ep.seed
                g.attrs["return"] = ep.total_return
                g.attrs["length"] = ep.length
                g.attrs["success"] = json.dumps(ep.success)
                decisions = ep.decisions
                T = len(decisions)
                g["observations"] = np.stack(ep.observations[:T]).astype(np.float32)
                g["rewards"] = np.asarray(ep.rewards, np.float64)
                g["ood"] = np.asarray(ep.ood, bool)
                if len(ep.measured) == T and T:         # the cells the environment measured
                    g["measured"] = np.stack(ep.measured)
                for key, idx in (("history_observations", 0), ("history_actions", 1),
                                 ("history_rewards", 2), ("history_mask", 3)):
                    g[key] = np.concatenate([h[idx] for h in ep.histories])
                if not decisions or decisions[0] is None:
                    continue
                m = max(len(d.support_rows) for d in decisions)
                rows = np.full((T, m), -1, np.int64)
                weights = np.zeros((T, m))
                dist = np.full((T, m), np.nan)
                for t, d in enumerate(decisions):
                    n = len(d.support_rows)
                    rows[t, :n], weights[t, :n], dist[t, :n] = (
                        d.support_rows, d.support_weights, d.support_distances)
                g["support_rows"], g["support_weights"], g["support_distances"] = rows, weights, dist
                ids = None if corpus is None else episode_ids(corpus)
                if ids is not None:
                    eps = corpus.episode_of(np.maximum(rows, 0))
                    g["support_episode_ids"] = np.where(
                        rows >= 0, np.asarray(ids, dtype=object)[eps], "").astype(
                        h5py.string_dtype())
                g["actions"] = np.stack([np.asarray(d.action) for d in decisions])
                g["values"] = np.array([np.nan if d.value is None else d.value
                                        for d in decisions])
                g["residuals"] = np.array([d.residual for d in decisions])
                if len(decisions[0].candidates):
                    g["candidates"] = np.stack([d.candidates for d in decisions])
                g["warnings"] = np.array([json.dumps(d.warnings) for d in decisions],
                                         dtype=h5py.string_dtype())


def read_audit_step(path, episode: int, step: int) -> dict:
    """The inputs and recorded outputs of one decision from an audit log."""
    with _open_audit(path) as f:
        meta = json.loads(f.attrs.get("meta", "{}"))
        key = f"episode_{episode}"
        if key not in f:
            eps = sorted(int(k.split("_")[1]) for k in f if k.startswith("episode_"))
            raise AocError(f"audit log {path} has no episode {episode} (episodes: {eps})")
        g = f[key]
        T = len(g["rewards"])
        if not 0 <= step < T or "residuals" not in g:
            raise AocError(f"episode {episode} of {path} has steps 0..{T - 1} "
                           "with decisions; no step {step}".replace("{step}", str(step)))
        hist = History(g["history_observations"][step][None], g["history_actions"][step][None],
                       g["history_rewards"][step][None], g["history_mask"][step][None])
        out = {
            "meta": meta,
            "observation": g["observations"][step],
            "history": hist,
            "action": g["actions"][step],
            "value": float(g["values"][step]),
            "residual": float(g["residuals"][step]),
            "support_rows": g["support_rows"][step],
            "support_weights": g["support_weights"][step],
            "candidates": g["candidates"][step] if "candidates" in g else None,
            "selection": _selection(f, meta),
            "measured": g["measured"][step] if "measured" in g else None,
        }
    return out


def _selection(f: h5py.File, meta: dict):
    """The recorded row selection: an (N,) bool mask, a list of row indices (logs written
    before the mask was kept, under 10,000 rows), "lost" (such a log of more rows: only a
    marker was kept), or None (every row)."""
    if "selection" in f:
        n = int(f["selection"].attrs["rows"])
        return np.unpackbits(f["selection"][()], count=n).astype(bool)
    kept = meta.get("selection")
    if kept is None:
        return None
    return "lost" if isinstance(kept, str) else list(kept)


@dataclass
class AuditEpisode:
    """The recorded decisions of one episode: ``residuals`` (T,), ``actions`` (T,) or (T, d_a),
    ``values`` (T,) (NaN in imitation mode), ``ood`` (T,) bool flagged steps,
    ``support_rows`` / ``support_weights`` (T, m), -1 / 0 padded."""

    residuals: np.ndarray
    actions: np.ndarray
    values: np.ndarray
    ood: np.ndarray
    support_rows: np.ndarray
    support_weights: np.ndarray


def read_audit_episode(path, episode: int) -> AuditEpisode:
    """The recorded decisions of episode ``episode`` of an audit log (an overview page's)."""
    with _open_audit(path) as f:
        key = f"episode_{episode}"
        if key not in f or "residuals" not in f[key]:
            eps = sorted(int(k.split("_")[1]) for k in f
                         if k.startswith("episode_") and "residuals" in f[k])
            raise AocError(f"audit log {path} has no decisions of episode {episode} "
                           f"(episodes: {eps})")
        g = f[key]
        residuals = np.asarray(g["residuals"], np.float64)
        return AuditEpisode(residuals, np.asarray(g["actions"]),
                            np.asarray(g["values"], np.float64),
                            np.asarray(g["ood"], bool)[:len(residuals)],
                            np.asarray(g["support_rows"]), np.asarray(g["support_weights"]))


def recorded_selection(recorded: dict, corpus, path) -> np.ndarray | None:
    """The (N,) bool row mask a recorded decision (:func:`read_audit_step`) was made from, or
    None for every row; an AocError where the log cannot say or does not fit ``corpus``."""
    kept = recorded["selection"]
    if kept is None:
        return None
    if isinstance(kept, str):
        raise AocError(f"audit log {path} was recorded from a selection of the corpus rows "
                       f"that it does not hold (written by an older aoc): record it again "
                       f"with `{call('rollout', '...', audit='FILE')}`")
    if isinstance(kept, list):                  # rows listed by an older aoc
        rows = np.asarray(kept, np.int64)
        kept = np.zeros(max(corpus.n_rows, int(rows.max(initial=-1)) + 1), bool)
        kept[rows] = True
    if len(kept) != corpus.n_rows:
        raise AocError(f"audit log {path} was recorded from a corpus of {len(kept)} rows, "
                       f"{corpus.name!r} has {corpus.n_rows}: it cannot be replayed against it")
    return kept


def read_audit_residuals(path) -> tuple[dict, list[np.ndarray]]:
    """(meta, per-episode residuals (T_e,)) of every episode of an audit log that has them."""
    with _open_audit(path) as f:
        meta = json.loads(f.attrs.get("meta", "{}"))
        keys = sorted((k for k in f if k.startswith("episode_")),
                      key=lambda k: int(k.split("_")[1]))
        runs = [np.asarray(f[k]["residuals"], np.float64) for k in keys if "residuals" in f[k]]
    if not runs:
        raise BadInput(path, f"audit log {path} holds no decisions with residuals (record it "
                       f"with `{call('rollout', '...', audit='FILE')}` using the AOC controller)")
    return meta, runs


def _open_audit(path) -> h5py.File:
    """An audit log open for reading, or AocError saying why it cannot be read."""
    if not Path(path).is_file():
        raise BadInput(path, f"audit log {path} does not exist: record one with "
                       f"`{call('rollout', 'NAME', env='ENV', audit='FILE')}`")
    try:
        return h5py.File(path, "r")
    except (OSError, FileNotFoundError) as err:
        raise AocError(f"cannot read audit log {path}: {err}") from None
