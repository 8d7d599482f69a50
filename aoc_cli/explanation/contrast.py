"""The contrast of a decision: the best action that was not chosen, with its own supporting
rows, v_hat and residual, and why it lost.

Value mode (AOC): every candidate has its own decomposition. The contrast is the candidate of
the highest v_hat other than the chosen one (ties: the smaller residual); it lost either to the
filter (its residual above the epsilon threshold, or fewer supporting episodes than
``--min-support``) or, having passed, by a lower v_hat (or an equal v_hat and a larger
residual; with ``--support-penalty``, a lower penalised v_hat). Its record is :func:`aoc_cli.control.decision_record` of that candidate explained
alone (as ``aoc explain --compare`` gives), with v_hat and residual as the decision compared
them, and the key ``why``.

Imitation of discrete actions (ABC): one decomposition decides; each action's score is the
weight of its rows in the minimal corpus subset. The contrast is the action of the next
highest score, its supporting rows are the subset's rows of that action, and it lost by a
lower score. Continuous imitation has no contrast (the decision is a weighted mean).
"""

from __future__ import annotations

import numpy as np

from aoc_cli.control.controller import Controller, Decision
from aoc_cli.control.records import decision_record
from aoc_cli.control.support import penalised
from aoc_cli.store import History


def contrast_record(controller: Controller, observation: np.ndarray, history: History,
                    decision: Decision, corpus, index, selection: np.ndarray | None = None,
                    typical_residual: float | None = None) -> dict | None:
    """The record of the best action not chosen by ``decision`` (None when there is none:
    a single candidate, an explained given action, continuous imitation)."""
    if controller.model.mode == "imitation":
        return _imitation_contrast(decision, corpus, index, controller)
    if len(decision.candidates) < 2 or not np.isfinite(decision.threshold):
        return None
    value, residual = decision.candidate_values, decision.candidate_residuals
    others = np.flatnonzero(np.arange(len(value)) != decision.chosen)
    j = int(others[np.lexsort((residual[others], -value[others]))[0]])
    observation = np.asarray(observation, dtype=np.float32).reshape(-1)
    alone = controller.decompose_candidates(observation, history,
                                            decision.candidates[j:j + 1], choose=False,
                                            selection=selection)
    rec = decision_record(alone, corpus, index, observation=None,
                          typical_residual=typical_residual)
    rec.pop("observation", None)
    # v_hat and residual as the decision compared them (one batch of K beliefs); the rows
    # from the action explained alone, whose float32 belief may differ in its last bits
    rec["value"], rec["residual"] = float(value[j]), float(residual[j])
    rec["candidate"] = j
    rec["passed"] = bool(decision.passed[j])
    rec["why"] = (_why_bound(decision, j, controller, observation) if decision.kept is not None
                  else _why_value(decision, j, controller))
    return rec


def _why_bound(d: Decision, j: int, controller: Controller, observation: np.ndarray) -> dict:
    """Why candidate ``j`` lost under rule 7: its lower bound over the log's rows near the
    step (none: no stay there received it) against the chosen action's."""
    near = controller.neighbourhood.at(observation[None],
                                       None if d.measured is None else d.measured[None])
    bounds = controller.neighbourhood.bounds(near)[0]
    mine, chosen = float(bounds[j]), float(bounds[d.chosen])
    out = {"value_gap": float(d.candidate_values[d.chosen] - d.candidate_values[j]),
           "threshold": d.threshold, "bound": mine, "chosen_bound": chosen,
           "episodes": int(near.episodes[0, j])}
    if not np.isfinite(mine):
        out["reason"] = "no nearby stay received it"
        out["text"] = (f"none of the log's {near.rows.sizes[0]} rows near this step "
                       "received it: rule 7 gives it no bound")
    else:
        out["reason"] = "lower bound"
        out["text"] = (f"its lower bound over the {int(near.episodes[0, j])} nearby stays that "
                       f"received it is {mine:.4g}, not above the chosen action's {chosen:.4g} "
                       "(rule 7)")
    return out


def _why_value(d: Decision, j: int, controller: Controller) -> dict:
    """Why candidate ``j`` lost to the chosen one: ``reason`` and the figures behind it."""
    r, v = float(d.candidate_residuals[j]), float(d.candidate_values[j])
    chosen_v = float(d.candidate_values[d.chosen])
    out = {"value_gap": chosen_v - v, "threshold": d.threshold}
    if not d.passed[j]:
        if r > d.threshold + 1e-12 * max(1.0, d.threshold):
            out["reason"] = "filtered by epsilon"
            out["text"] = (f"its residual {r:.3g} is above the epsilon threshold "
                           f"{d.threshold:.3g} (it extrapolates further than the "
                           f"{controller.config.epsilon:.0%} closest candidates)")
        else:
            out["reason"] = "filtered by min support"
            out["text"] = (f"backed by {float(d.candidate_support[j]):.2g} episodes, fewer "
                           f"than --min-support {controller.config.min_support}")
    elif controller.config.support_penalty is not None:
        key = penalised(d.candidate_values, d.candidate_support,
                        controller.config.support_penalty, controller.value_std)
        out["reason"] = "lower penalised v_hat"
        out["text"] = (f"its v_hat {v:.4g} shrunk by its {float(d.candidate_support[j]):.3g} "
                       f"episodes is {float(key[j]):.4g}, below the chosen action's "
                       f"{float(key[d.chosen]):.4g} (--support-penalty "
                       f"{controller.config.support_penalty:g})")
    elif v < chosen_v:
        out["reason"] = "lower v_hat"
        out["text"] = f"its v_hat {v:.4g} is below the chosen action's {chosen_v:.4g}"
    else:
        out["reason"] = "equal v_hat, larger residual"
        out["text"] = (f"the same v_hat {v:.4g} with a larger residual {r:.3g} than the "
                       f"chosen action's {float(d.candidate_residuals[d.chosen]):.3g}")
    return out


def _imitation_contrast(d: Decision, corpus, index, controller: Controller) -> dict | None:
    if not corpus.discrete or not len(d.support_rows):
        return None
    actions = np.asarray(controller.corpus_actions)[d.support_rows].astype(np.int64)
    scores = (d.scores if len(d.scores) else
              np.bincount(actions, weights=d.support_weights, minlength=int(corpus.n_actions)))
    chosen = int(np.asarray(d.action))
    scores_others = scores.copy()
    scores_others[chosen] = -np.inf
    other = int(np.argmax(scores_others))
    mine = actions == other
    lost = Decision(action=np.asarray(other), value=None, residual=d.residual,
                    support_rows=d.support_rows[mine], support_weights=d.support_weights[mine],
                    support_distances=d.support_distances[mine],
                    support_labels=(d.support_labels[mine] if len(d.support_labels)
                                    else np.empty((0, 0))), candidates=np.empty(0),
                    candidate_residuals=np.empty(0), candidate_values=np.empty(0),
                    passed=np.empty(0, bool), chosen=-1, threshold=float("nan"))
    rec = decision_record(lost, corpus, index)
    rec.pop("observation", None)
    rec["score"] = float(scores[other])
    rec["why"] = {"reason": "lower score", "score_gap": float(scores[chosen] - scores[other]),
                  "text": (f"its score over the subset's rows is {scores[other]:.0%}, the "
                           f"chosen action's {scores[chosen]:.0%}")}
    return rec
