"""ABC's scores of discrete actions from the named rows of a minimal corpus subset.

A decision of ABC names its minimal corpus subset: rows c with barycentric weights w^c. The
score of action a is what those rows carry of it,

    score(a) = sum_c w^c l^c(a),     l^c = (1 - lambda) onehot(a^c) + lambda softmax(l(b^c)),

each row's *label* l^c (n,) its logged action a^c smoothed towards the belief's own probability
of each action at that row's belief b^c (the linear head l, the model ABC explains). lambda = 0
is the paper's score, each action's weight in the subset; the decision is the score's argmax
either way, and the score is exactly the sum over the named rows, each row's label shown with
it (``aoc explain``). Why smoothed (docs/design.md, "Row labels"): a held-out belief projects on
a face of ~8 rows, and the clinicians' logged choices near their thresholds are noisy, so the
subset's logged actions rank the steps worse than the belief does at the same rows (ward, log 1:
held-out AUC 0.954 against the head's 0.973); the rows' labels smoothed with lambda
:data:`ROW_SMOOTHING` rank as the belief does (0.973) while the rows stay the decision's.
"""

from __future__ import annotations

import numpy as np

#: lambda for discrete imitation with the candidates of every action (small logs; chosen by
#: the validation AUC of ABC on the training patients of two ward logs: docs/design.md).
ROW_SMOOTHING = 0.75


def default_row_smoothing(discrete: bool, candidates: str | None) -> float:
    """lambda when none is given: :data:`ROW_SMOOTHING` for discrete imitation whose index
    takes the candidates of every action (``candidates`` "per_action"), where it was measured;
    else 0 (the paper's score: each action's weight in the subset)."""
    return ROW_SMOOTHING if discrete and candidates == "per_action" else 0.0


def row_labels(actions: np.ndarray, beliefs: np.ndarray | None, head, n_actions: int,
               smoothing: float) -> np.ndarray:
    """(m, n) the labels l^c of rows with logged ``actions`` (m,) int and ``beliefs``
    (m, d_b); ``head`` the logits' linear head, (weight (n, d_b), bias (n,)) (a
    :class:`aoc_cli.belief.artefact.LinearHead` or a pair).
    With ``smoothing`` 0 the one-hot logged actions (``beliefs`` and ``head`` unread)."""
    actions = np.asarray(actions, dtype=np.int64).reshape(-1)
    labels = np.zeros((len(actions), n_actions))
    labels[np.arange(len(actions)), actions] = 1.0
    if smoothing == 0 or not len(actions):
        return labels
    weight, bias = head
    z = np.asarray(beliefs, dtype=np.float64) @ np.asarray(weight).T + np.asarray(bias)
    p = np.exp(z - z.max(1, keepdims=True))
    p /= p.sum(1, keepdims=True)
    return (1.0 - smoothing) * labels + smoothing * p


def subset_scores(rows: np.ndarray, weights: np.ndarray, actions: np.ndarray, n_actions: int,
                  beliefs: np.ndarray | None = None, head=None,
                  smoothing: float = 0.0) -> np.ndarray:
    """(Q, n) each action's score in the minimal corpus subsets ``rows`` (Q, m) (-1 padded)
    with ``weights`` (Q, m): sum_c w^c l^c over the named rows (:func:`row_labels`);
    ``actions`` (N,) the corpus rows' actions, ``beliefs`` (N, d_b) the corpus beliefs (read
    only where ``smoothing`` > 0, for the named rows alone)."""
    rows = np.asarray(rows)
    used = rows >= 0
    picked = np.maximum(rows, 0)[used]
    lab = row_labels(np.asarray(actions)[picked],
                     None if smoothing == 0 else np.asarray(beliefs)[picked], head, n_actions,
                     smoothing)
    scores = np.zeros((len(rows), n_actions))
    np.add.at(scores, np.nonzero(used)[0], np.asarray(weights)[used][:, None] * lab)
    return scores
