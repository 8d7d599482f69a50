"""Decision records (what a person audits) and the audit log (HDF5, written atomically).

A record holds the decision, its value estimate and residual, one entry per supporting corpus
row (row, episode, step, tags, action, value, weight, distance; discrete imitation: its label,
and the record the actions' scores, aoc_cli.belief.row_labels), a summary of the other
candidates and the warnings. The audit log keeps, for every step of every episode, the inputs
of the decision (observation, history, candidates) and its outputs, so any recorded decision
can be re-run and explained again.
"""

from __future__ import annotations

import json

import h5py
import numpy as np

from aoc_cli.control.controller import Decision
from aoc_cli.errors import AocError, BadInput, call
from aoc_cli.store import History, action_labels, atomic_path


def episode_ids(corpus) -> list[str] | None:
    """The corpus's own episode ids (e.g. patient ids kept by a CSV ingest), one per episode,
    or None when it has none."""
    return getattr(corpus, "episode_ids", None)


def decision_record(decision: Decision, corpus, index, step: int | None = None,
                    observation: np.ndarray | None = None, typical_residual: float | None = None
                    ) -> dict:
    """A JSON-ready description of one decision."""
    rows = decision.support_rows
    episodes = corpus.episode_of(rows) if len(rows) else np.empty(0, np.int64)
    timesteps = corpus.timesteps[rows] if len(rows) else np.empty(0, np.int64)
    tags = corpus.tag_labels_of(rows) if len(rows) else {}
    ids = episode_ids(corpus)
    actions = corpus.actions[rows] if len(rows) else np.empty(0)
    labels = action_labels(corpus.action_space)
    values = index.values[rows] if index.values is not None and len(rows) else None
    counts = decision.support_counts
    support = []
    for j, row in enumerate(rows):
        support.append({
            "row": int(row),
            "episode": int(episodes[j]),
            "episode_id": None if ids is None else ids[int(episodes[j])],
            "step": int(timesteps[j]),
            "tags": {name: labels[j] for name, labels in tags.items()},
            "action": np.asarray(actions[j]).tolist(),
            **label_of(labels, actions[j]),
            "value": None if values is None else float(values[j]),
            "weight": float(decision.support_weights[j]),
            "distance": float(decision.support_distances[j]),
            "episodes_here": int(counts[j]) if j < len(counts) else None,
            **({"label": decision.support_labels[j].tolist()}
               if len(decision.support_labels) else {}),
        })
    support.sort(key=lambda s: -s["weight"])
    record = {
        "step": step,
        "observation": None if observation is None else np.asarray(observation).tolist(),
        "action": np.asarray(decision.action).tolist(),
        **label_of(labels, decision.action),
        "value": decision.value,
        "residual": decision.residual,
        "typical_residual": typical_residual,
        "support_episodes": None if not np.isfinite(decision.support) else decision.support,
        "support": support,
        "warnings": list(decision.warnings),
    }
    if len(decision.scores):  # discrete imitation: sum over the rows of weight x label
        record["scores"] = decision.scores.tolist()
    if typical_residual and decision.residual > 3 * typical_residual:
        record["warnings"].append(
            f"large residual: {decision.residual:.3g} is over 3x the corpus's typical "
            f"{typical_residual:.3g} (the decision extrapolates)")
    if len(decision.candidates) and decision.chosen >= 0:
        rejected = ~decision.passed
        record["candidates"] = {
            "count": int(len(decision.candidates)),
            "passed": int(decision.passed.sum()),
            "threshold": decision.threshold,
            "best_rejected_value": float(decision.candidate_values[rejected].max())
            if rejected.any() else None,
        }
    return record


def label_of(labels: list[str] | None, action, key: str = "action_label") -> dict:
    """``{key: the action's label}`` for a corpus whose discrete actions are labelled
    (:func:`aoc_cli.store.action_labels`), else ``{}``."""
    if labels is None:
        return {}
    code = int(np.asarray(action).reshape(-1)[0])
    return {key: labels[code] if 0 <= code < len(labels) else None}


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
    from pathlib import Path

    if not Path(path).is_file():
        raise BadInput(path, f"audit log {path} does not exist: record one with "
                       f"`{call('rollout', 'NAME', env='ENV', audit='FILE')}`")
    try:
        return h5py.File(path, "r")
    except (OSError, FileNotFoundError) as err:
        raise AocError(f"cannot read audit log {path}: {err}") from None
