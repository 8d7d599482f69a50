"""The k rule: how many nearest corpus rows a query searches in step 1 of the decomposition
(the rows its weights are found among). Its one home: the index records the k it is built
with (:func:`index_k`, through :func:`aoc_cli.index.model_k`), a decomposition given
no k falls back to the paper's, training's validation decomposes as the index will, and the
baselines that use another k say so by calling these functions with their own arguments
(:func:`aoc_cli.baselines.neighbours.knn_k`, evaluate's kNN baseline).

* the paper's k = 2 (d_b + 1): twice the size of a minimal corpus subset (:func:`default_k`);
* an imitation model of discrete actions on a small log (at most :data:`SMALL_MAX_ROWS`
  rows): the 3 (d_b + 1) nearest rows *of each action* present, n 3 (d_b + 1)
  (:func:`per_action_k`; :mod:`aoc_cli.index.search.strata`);
* the same on a larger log: (d_b + 1) / the rarest action's share, between the paper's k and
  :data:`MAX_K_FACTOR` (d_b + 1) (:func:`default_k` with ``rarest_share``).

docs/design.md, "Candidates of every action".
"""

from __future__ import annotations

import numpy as np

from aoc_cli.index.search.strata import NEAREST, PER_ACTION
from aoc_cli.settings import SMALL_LOG_ROWS

#: The most neighbours :func:`default_k` asks for, as a multiple of d_b + 1.
MAX_K_FACTOR = 16
#: Up to this many rows an imitation index of discrete actions takes the nearest rows of each
#: action (:data:`aoc_cli.settings.SMALL_LOG_ROWS`).
SMALL_MAX_ROWS = SMALL_LOG_ROWS


def subset_size(d_b: int) -> int:
    """d_b + 1: the most rows a minimal corpus subset holds (Caratheodory in d_b dimensions)."""
    return int(d_b) + 1


def default_k(d_b: int, rarest_share: float | None = None) -> int:
    """Neighbours per query: the paper's k = 2 (d_b + 1) (twice the size of a minimal corpus
    subset). With ``rarest_share`` (discrete imitation: the share of the corpus rows that
    hold its rarest action), at least (d_b + 1) / rarest_share, so that a neighbourhood at the
    corpus's base rates holds a full minimal subset's worth (d_b + 1) of rows of every action,
    and at most 16 (d_b + 1). Balanced binary actions give the paper's k; ward's treatment
    (11% of rows, d_b = 20) gives 191. Imitation logs of up to 20,000 rows take the nearest
    rows of each action instead (:func:`per_action_k`)."""
    d1 = subset_size(d_b)
    k = 2 * d1
    if rarest_share is not None and rarest_share > 0:
        k = min(max(k, int(np.ceil(d1 / float(rarest_share)))), MAX_K_FACTOR * d1)
    return k


#: Rows of each action step 1 takes on a small imitation log, as a multiple of d_b + 1 (ward:
#: 63 of each): chosen by validation on the training patients of two ward logs, 20 splits
#: (docs/design.md, "Candidates of every action").
PER_ACTION_FACTOR = 3


def per_action_k(d_b: int, n_actions: int) -> int:
    """The :data:`PER_ACTION_FACTOR` (d_b + 1) nearest rows of each of ``n_actions`` actions
    present (at least one): n 3 (d_b + 1) rows in all."""
    return max(int(n_actions), 1) * PER_ACTION_FACTOR * subset_size(d_b)


def rarest_share(actions: np.ndarray) -> float | None:
    """The share of the rows (N,) of discrete ``actions`` that hold the rarest action present
    (None for no rows): what :func:`default_k` scales the imitation k by."""
    counts = np.bincount(np.asarray(actions, dtype=np.int64))
    counts = counts[counts > 0]
    return float(counts.min() / counts.sum()) if len(counts) else None


def index_k(d_b: int, corpus, imitation: bool, candidates: str = "auto") -> tuple[int, str]:
    """The k of an index of a model with ``d_b``-dimensional beliefs on ``corpus`` (its
    ``actions`` and ``n_rows``, read only when the rule needs them), and how step 1 takes its
    candidates: "nearest" (the k nearest rows) or "per_action" (the 3 (d_b + 1) nearest of each
    action). ``imitation``: the model imitates the corpus's discrete actions. ``candidates``:
    "auto" (the rule of the module docstring), "nearest" (the paper's k) or "per_action"."""
    if candidates == PER_ACTION or (candidates == "auto" and imitation
                                    and corpus.n_rows <= SMALL_MAX_ROWS):
        n = int(np.count_nonzero(np.bincount(np.asarray(corpus.actions, dtype=np.int64))))
        return per_action_k(d_b, n), PER_ACTION
    if candidates == "auto" and imitation:
        return default_k(d_b, rarest_share(corpus.actions)), NEAREST
    return default_k(d_b), NEAREST
