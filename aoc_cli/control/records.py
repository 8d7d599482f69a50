"""Decision records: what a person audits of one decision.

A record holds the decision, its value estimate and residual, one entry per supporting corpus
row (row, episode, step, tags, action, value, weight, distance; discrete imitation: its label,
and the record the actions' scores, aoc_cli.belief.row_labels), a summary of the other
candidates and the warnings. The audit log of a rollout's decisions is
:mod:`aoc_cli.control.audit`'s.
"""

from __future__ import annotations

import numpy as np

from aoc_cli.control.controller import Decision
from aoc_cli.store import action_labels


def episode_ids(corpus) -> list[str] | None:
    """The corpus's own episode ids (e.g. patient ids kept by a CSV ingest), one per episode,
    or None when it has none."""
    return getattr(corpus, "episode_ids", None)


#: What a decision rule 7 kept says (aoc explain, the decision page).
KEPT = "kept the clinicians' dose: no better-supported alternative"


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
    if decision.kept is not None:   # rule 7, do no harm
        record["rule"] = (KEPT if decision.kept else
                          "a better-supported alternative: its lower bound beat the "
                          "clinicians' likely dose's own")
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
