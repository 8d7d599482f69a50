"""How many patients back a value: the support of a decomposition, and the filter on it.

The corpus residual says how far a candidate's belief lies from the hull of the corpus; it
cannot say how many episodes stand behind the hull's vertices. Where states repeat exactly (a
log over a discrete state space, ICU-Sepsis), every logged (state, action) has residual 0,
whether one patient or fifty took it, and the rarely tried actions' values are noise. The
*support* of a decomposition is the effective number of distinct episodes behind its value
v_hat = sum_c w^c v^c (docs/design.md, "The method, precisely")::

    n_c     = distinct episodes with a row at vertex c's belief (||b_j - b^c|| <= tol,
              among the query's k nearest rows; at least c's own episode)
    support = 1 / sum_c ( (w^c)^2 / n_c )

Kish's effective sample size of the weighted mean when each vertex's value is itself a mean
over n_c episodes: one vertex backed by n episodes gives n; d_b + 1 distinct rows of equal
weight give d_b + 1; a hull of rows seen once gives at most d_b + 1. It is bounded by k, the
rows searched (2 (d_b + 1) by default).

Two rules use it, both opt-in. With ``min_support`` m the controller keeps the candidates
whose residual passes the epsilon filter *and* whose support is at least m; when none has m,
the best supported of those that pass the residual filter (:func:`support_filter`). With
``support_penalty`` z it ranks the candidates that pass by a value shrunk by how many episodes
back it (:func:`penalised`), a lower bound in the corpus's own value scale::

    v_hat(a) - z sigma_v / sqrt(support(a)),     sigma_v = std of the corpus values v^c
"""

from __future__ import annotations

import numpy as np

#: Two beliefs are the same point when within this share of (1 + the vertex's norm).
SAME_POINT = 1e-5
#: Queries per block of the (Q, m, k) distances.
_BLOCK = 4096


def row_episodes(episode_starts: np.ndarray) -> np.ndarray:
    """(N,) int64: the episode of every corpus row, from the (E + 1,) episode offsets."""
    starts = np.asarray(episode_starts, dtype=np.int64)
    return np.repeat(np.arange(len(starts) - 1, dtype=np.int64), np.diff(starts))


def support_episodes(beliefs: np.ndarray, rows: np.ndarray, weights: np.ndarray,
                     neighbours: np.ndarray, row_episode: np.ndarray
                     ) -> tuple[np.ndarray, np.ndarray]:
    """(Q,) float64 effective number of distinct episodes behind each decomposition, and
    (Q, m) int64 n_c of each vertex of its subset (0 where padded).

    beliefs (N, d_b) corpus beliefs; rows, weights (Q, m) the minimal corpus subsets (-1 / 0
    padded); neighbours (Q, k) the rows searched (-1 padded); row_episode (N,) episode of
    each row. A vertex's n_c counts the distinct episodes among the neighbours within
    ``SAME_POINT`` of it (module docstring).
    """
    rows = np.asarray(rows, np.int64)
    neighbours = np.asarray(neighbours, np.int64)
    out = np.zeros(len(rows))
    counts = np.zeros(rows.shape, np.int64)
    for a in range(0, len(rows), _BLOCK):
        out[a:a + _BLOCK], counts[a:a + _BLOCK] = _support_block(
            beliefs, rows[a:a + _BLOCK], np.asarray(weights[a:a + _BLOCK], np.float64),
            neighbours[a:a + _BLOCK], row_episode)
    return out, counts


def _support_block(beliefs, rows, weights, neighbours, row_episode) -> np.ndarray:
    used = rows >= 0
    valid = neighbours >= 0
    v = np.asarray(beliefs[np.maximum(rows, 0).ravel()], np.float64).reshape(rows.shape + (-1,))
    b = np.asarray(beliefs[np.maximum(neighbours, 0).ravel()],
                   np.float64).reshape(neighbours.shape + (-1,))
    # (q, m, k) squared distances between the subset's vertices and the searched rows, by
    # the expansion (no (q, m, k, d) temporary; its rounding, ~1e-16 of the norms squared,
    # is far below the tolerance's square)
    vv = (v ** 2).sum(-1)                                                    # (q, m)
    sq = vv[:, :, None] + (b ** 2).sum(-1)[:, None, :] - 2.0 * np.einsum("qmd,qkd->qmk", v, b)
    tol = SAME_POINT * (1.0 + np.sqrt(vv))                                   # (q, m)
    same = (sq <= (tol ** 2)[:, :, None]) & valid[:, None, :] & used[:, :, None]
    eps = row_episode[np.maximum(neighbours, 0)]                             # (q, k)
    # distinct episodes per vertex: sort each vertex's episodes (-1 for rows not at it)
    marked = np.sort(np.where(same, eps[:, None, :], -1), axis=2)            # (q, m, k)
    new = np.concatenate([marked[..., :1] >= 0,
                          (marked[..., 1:] != marked[..., :-1]) & (marked[..., 1:] >= 0)],
                         axis=2)
    n_c = np.where(used, np.maximum(new.sum(2), 1), 0)                       # (q, m)
    inv = np.where(used, weights ** 2 / np.maximum(n_c, 1), 0.0).sum(1)
    return np.where(inv > 0, 1.0 / np.where(inv > 0, inv, 1.0), 0.0), n_c


def support_filter(passed: np.ndarray, support: np.ndarray, min_support: float | None
                   ) -> np.ndarray:
    """(..., K) bool: the candidates that pass the residual filter (``passed``) and have a
    support of at least ``min_support``; where none of a step's does, those of its passing
    candidates with the largest support. ``min_support`` None: ``passed`` unchanged."""
    if min_support is None:
        return passed
    passed = np.asarray(passed, bool)
    support = np.asarray(support, np.float64)
    enough = passed & (support >= float(min_support))
    best = np.where(passed, support, -np.inf).max(-1, keepdims=True)
    fallback = passed & (support >= best)
    none = ~enough.any(-1, keepdims=True)
    return np.where(none, fallback, enough)


def penalised(values: np.ndarray, support: np.ndarray, penalty: float | None,
              value_std: float) -> np.ndarray:
    """The ranking key ``v_hat - z sigma_v / sqrt(support)`` (support below 1 counts as 1);
    ``penalty`` None: the values unchanged."""
    if penalty is None:
        return values
    return values - float(penalty) * float(value_std) / np.sqrt(np.maximum(support, 1.0))
