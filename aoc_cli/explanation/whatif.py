"""Exact what-if: a decision re-decided without some corpus rows, no retraining.

A decision of AOC / ABC is non-parametric over the corpus: removing rows changes only which
rows step 1 may find, not the belief model. So "what if we had not had these patients" is
answered exactly by a row mask on the same index (:mod:`aoc_cli.rows`): the same query
beliefs, the same candidates (a continuous control step reuses the candidates it drew), the
decomposition searched among the remaining rows. A decision none of whose step-1 candidate
rows were removed is unchanged bit for bit; one that used them equals the decision over a
corpus rebuilt without them (same model, beliefs and index kind; tests/explanation/test_whatif.py).

:func:`removal` turns ``--without TAG=VALUE`` / ``--without-episodes ID,...`` into an (N,) bool
mask of the rows removed; :func:`redecide` re-runs one :class:`Decision` under the remaining
rows; :func:`what_if_record` says what changed (the JSON key ``what_if``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from aoc_cli.control.controller import Controller, Decision
from aoc_cli.errors import AocError
from aoc_cli.store import History


@dataclass
class Removal:
    """Rows taken out of the corpus for a what-if: ``mask`` (N,) bool, True where removed;
    ``label`` what the user asked (``clinician=c2; episodes p0001``)."""

    mask: np.ndarray
    label: str

    @property
    def rows(self) -> int:
        return int(self.mask.sum())

    def describe(self, corpus) -> dict:
        """JSON: what was removed (the ``what_if.without`` key)."""
        removed = np.flatnonzero(self.mask)
        episodes = np.unique(corpus.episode_of(removed)) if len(removed) else removed
        return {"label": self.label, "rows": int(len(removed)),
                "episodes": int(len(episodes))}

    def keep(self, selection: np.ndarray | None) -> np.ndarray:
        """(N,) bool: the rows a decision may use, ``selection`` (or every row) less these."""
        base = np.ones(len(self.mask), bool) if selection is None else np.asarray(selection, bool)
        keep = base & ~self.mask
        if not keep.any():
            raise AocError(f"removing {self.label} leaves no rows of the corpus to decide "
                           "with: remove fewer rows")
        return keep


def removal(corpus, without: dict[str, list[str]] | None = None,
            without_episodes: list[str] | None = None) -> Removal | None:
    """The rows of ``corpus`` to remove: those whose tag has one of the given values
    (``{"clinician": ["c2"]}``), and every row of the given episodes (the corpus's own episode
    ids, e.g. patient ids, or episode numbers). None when nothing is asked. An unknown tag, tag
    value or episode, or a removal of every row, is an AocError."""
    if not without and not without_episodes:
        return None
    n = corpus.n_rows
    mask = np.zeros(n, bool)
    parts = []
    for tag, labels in (without or {}).items():
        codes, known = corpus.tag(tag)
        for label in labels:
            if label not in known:
                raise AocError(f"tag {tag!r} has no value {label!r} (values: "
                               f"{', '.join(known)})", "without")
        mask |= np.isin(codes, [known.index(x) for x in labels])
        parts.append(f"{tag}={','.join(labels)}")
    if without_episodes:
        episodes = _episode_numbers(corpus, without_episodes)
        starts = np.asarray(corpus.episode_starts, np.int64)
        for e in episodes:
            mask[starts[e]:starts[e + 1]] = True
        parts.append("episodes " + ",".join(str(x) for x in without_episodes))
    label = "; ".join(parts)
    if mask.all():
        raise AocError(f"removing {label} removes every row of corpus {corpus.name!r}: "
                       "remove fewer rows", "without")
    return Removal(mask, label)


def _episode_numbers(corpus, items: list[str]) -> list[int]:
    """Episode numbers of ``items``: the corpus's own ids first, else numbers 0..E-1."""
    ids = getattr(corpus, "episode_ids", None)
    position = {str(x): i for i, x in enumerate(ids)} if ids is not None else {}
    out = []
    for item in items:
        item = str(item).strip()
        if item in position:
            out.append(position[item])
            continue
        try:
            e = int(item)
        except ValueError:
            e = -1
        if not 0 <= e < corpus.n_episodes:
            known = (f"ids such as {', '.join(map(str, ids[:3]))}" if ids is not None
                     else f"episodes 0..{corpus.n_episodes - 1}")
            raise AocError(f"corpus {corpus.name!r} has no episode {item!r} ({known})",
                           "without_episodes")
        out.append(e)
    return out


def redecide(controller: Controller, observation: np.ndarray, history: History,
             decision: Decision, selection: np.ndarray) -> Decision:
    """``decision`` decided again among the rows of ``selection`` (N,) bool: imitation, the
    same query; value mode, the same candidates, chosen by the same rule (or, for a decision
    that explained one given action, that action again)."""
    if controller.model.mode == "imitation":
        return controller.decide(observation, history, selection=selection)
    observation = np.asarray(observation, dtype=np.float32).reshape(-1)
    # a chosen decision has its epsilon threshold; an explained given action has none
    return controller.decompose_candidates(observation, history, decision.candidates,
                                           choose=bool(np.isfinite(decision.threshold)),
                                           selection=selection)


def what_if_record(before: dict, after: dict, removal: Removal, corpus) -> dict:
    """What changed between two decision records (:func:`aoc_cli.control.decision_record`) of
    the same query, before and after ``removal``: the JSON key ``what_if``."""
    removed = removal.mask
    before_rows = [s["row"] for s in before["support"]]
    out = {
        "without": removal.describe(corpus),
        "support_removed": [r for r in before_rows if removed[r]],
        "action": after["action"],
        "value": after["value"],
        "residual": after["residual"],
        "action_changed": after["action"] != before["action"],
        "value_change": None if after["value"] is None or before["value"] is None
        else after["value"] - before["value"],
        "residual_change": after["residual"] - before["residual"],
        "support": after["support"],
        "warnings": after["warnings"],
    }
    out["unchanged"] = bool(not out["action_changed"] and out["value_change"] in (None, 0.0)
                            and out["residual_change"] == 0.0
                            and [s["row"] for s in after["support"]] == before_rows)
    if "candidates" in after:
        out["candidates"] = after["candidates"]
    return out


def _spread(x: np.ndarray) -> dict:
    """Mean, mean absolute and largest absolute of a change (S,)."""
    x = np.asarray(x, np.float64)
    if not len(x):
        return {"mean": None, "mean_abs": None, "max_abs": None}
    return {"mean": float(x.mean()), "mean_abs": float(np.abs(x).mean()),
            "max_abs": float(np.abs(x).max())}


def what_if_steps(before, after, removal: Removal, corpus, summary_after: dict) -> dict:
    """What removing rows changes over every step of an evaluation: ``before`` and ``after``
    the :class:`aoc_cli.evaluation.step_scores.StepScores` of the same steps with every row and
    without ``removal``'s. The JSON key ``what_if`` of ``aoc evaluate --without``.

    ``flipped``: the steps whose decision differs (discrete: another action; continuous:
    any coordinate); ``value_change``: v_hat of the decision after - before (value mode);
    ``score_change``: the weight of the action decided before, after - before (discrete
    imitation); ``residual_change``: the decision's residual, after - before; ``support_
    removed_steps``: the steps whose minimal corpus subset held a removed row."""
    dec_b, dec_a = np.asarray(before.decided), np.asarray(after.decided)
    flipped = dec_b != dec_a
    if flipped.ndim > 1:
        flipped = flipped.reshape(len(flipped), -1).any(1)
    held = (before.support_rows >= 0) & removal.mask[np.maximum(before.support_rows, 0)]
    steps = int(len(flipped))
    out = {
        "without": removal.describe(corpus),
        "steps": steps,
        "flipped": int(flipped.sum()),
        "flip_share": float(flipped.mean()) if steps else None,
        "support_removed_steps": int(held.any(1).sum()),
        "residual_change": _spread(after.residual - before.residual),
    }
    if before.decided_value is not None:
        out["value_change"] = _spread(after.decided_value - before.decided_value)
    if before.scores is not None:
        idx = np.arange(steps)
        out["score_change"] = _spread(after.scores[idx, dec_b] - before.scores[idx, dec_b])
    keys = ("accuracy", "balanced_accuracy", "auc", "mae", "r2", "value_r2", "agreement",
            "extrapolating_share", "heterogeneity_share")
    out["after"] = {k: summary_after.get(k) for k in keys if summary_after.get(k) is not None}
    return out
