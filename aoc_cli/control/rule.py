"""The decision rule of value mode, steps 4 and 5 of a control step (docs/design.md, "The
method, precisely"), and the candidates it chooses among (:func:`candidate_actions`), written
once and batched: the controller calls it for one step
(:meth:`aoc_cli.control.Controller.decompose_candidates`, S = 1) and ``aoc evaluate`` for
every held-out step at once (:mod:`aoc_cli.evaluation.score`). Over the K candidates of each of S steps:

4. keep the candidates whose corpus residual is within the epsilon-quantile of the K
   residuals and, with a residual cap c, within c x the corpus's typical p90 residual
   (:func:`epsilon_filter`); with ``min_support`` m, of those the ones backed by at least m
   distinct episodes (:func:`aoc_cli.control.support.support_filter`);
5. the argmax of v_hat among them, or with ``support_penalty`` z of the penalised v_hat
   (:func:`aoc_cli.control.support.penalised`); ties: the smaller residual, then the first;
   with rule 7 (do no harm) the argmax of a lower bound over the actions the log's rows near
   the step took (they replace the residual filter), taken only where it beats the
   clinicians' likely action's own bound, else that action is kept (:func:`choose`).
"""

from __future__ import annotations

import numpy as np

from aoc_cli.control.config import ControllerConfig
from aoc_cli.errors import AocError
from aoc_cli.control.support import penalised, support_filter


def residual_cap(cap: float | None, typical_p90: float | None) -> float | None:
    """c x the corpus's typical p90 residual, or None (no cap set, or no p90 recorded)."""
    if cap is None or typical_p90 is None:
        return None
    return float(cap) * float(typical_p90)


def epsilon_filter(residual: np.ndarray, epsilon: float, cap: float | None = None
                   ) -> tuple[np.ndarray, np.ndarray]:
    """(threshold (..., 1), passed (..., K) bool) of the residuals (..., K) of K candidates:
    residual <= min(q_epsilon, cap) (up to 1e-12 relative). Where no candidate passes
    (possible only with the cap), the smallest-residual candidates pass and the threshold is
    their residual."""
    residual = np.asarray(residual)
    threshold = np.quantile(residual, epsilon, axis=-1, keepdims=True)
    if cap is not None:
        threshold = np.minimum(threshold, cap)
    passed = residual <= threshold + 1e-12 * np.maximum(1.0, threshold)
    empty = ~passed.any(axis=-1, keepdims=True)
    if empty.any():
        low = residual.min(axis=-1, keepdims=True)
        threshold = np.where(empty, low, threshold)
        passed = np.where(empty, residual <= low + 1e-12 * np.maximum(1.0, low), passed)
    return threshold, passed


def reads_support(config: ControllerConfig) -> bool:
    """Whether the rule reads the candidates' support (``min_support`` or
    ``support_penalty`` set): only then need a caller compute it."""
    return config.min_support is not None or config.support_penalty is not None


def choose(residual: np.ndarray, value: np.ndarray, config: ControllerConfig, *,
           cap: float | None = None, support: np.ndarray | None = None,
           value_std: float = 1.0, lower: np.ndarray | None = None,
           kept: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The decision among the K candidates of each of S steps (module docstring).

    residual, value (S, K) float64: each candidate's corpus residual and v_hat; ``config``:
    epsilon, min_support, support_penalty; ``cap``: the absolute residual cap
    (:func:`residual_cap`: c x the typical p90) or None; ``support`` (S, K): each
    candidate's support (needed when :func:`reads_support`); ``value_std``: sigma_v of the
    penalty. Rule 7, do no harm (discrete actions, the candidates every action):
    ``lower`` (S, K) each candidate's lower bound (the rank key in place of v_hat, or of the
    penalised v_hat; the candidates it bounds, finite, are those that pass) and ``kept`` (S,)
    the clinicians' likely action (:mod:`aoc_cli.index.search.neighbourhood`): the
    best-ranked candidate is taken only where its key beats the kept action's own bound (its
    v_hat where no ``lower`` is given: rule 2's key ranks), else the kept action is; the
    residual plays no part in it (the first of equal bounds). Returns (threshold (S, 1),
    passed (S, K) bool, chosen (S,) int64)."""
    residual = np.asarray(residual, np.float64)
    value = np.asarray(value, np.float64)
    threshold, passed = epsilon_filter(residual, config.epsilon, cap)
    key = value
    if reads_support(config):
        passed = support_filter(passed, support, config.min_support)
        key = penalised(value, support, config.support_penalty, value_std)
    if lower is not None:   # rule 7: the neighbourhood's episodes are the support
        key = np.asarray(lower, np.float64)
        passed = np.isfinite(key)
    key = np.where(passed, key, -np.inf)
    best = key.max(-1, keepdims=True)
    if lower is not None and kept is not None:
        chosen = key.argmax(-1)   # rule 7 reads no residual: ties go to the kept action below
    else:   # of the best (penalised) v_hat the smaller residual; argmin: the first of equals
        chosen = np.where(key == best, residual, np.inf).argmin(-1)
    if kept is not None:
        s = np.arange(len(chosen))
        kept = np.asarray(kept, np.int64)
        base = (value if lower is None else np.asarray(lower, np.float64))[s, kept]
        chosen = np.where(key[s, chosen] > base, chosen, kept)
    return threshold, passed, chosen


# -- the candidates of a step (steps 1-2) ------------------------------------------------

def action_bounds(action_space: dict, actions: np.ndarray | None = None):
    """(low (d_a,), high (d_a,)) of a box action space; from the data when not recorded."""
    if "low" in action_space and "high" in action_space:
        low = np.asarray(action_space["low"], dtype=np.float64)
        high = np.asarray(action_space["high"], dtype=np.float64)
        if np.all(np.isfinite(low)) and np.all(np.isfinite(high)):
            return low, high
    if actions is None:
        raise AocError("the action space has no bounds: cannot sample candidates")
    return actions.min(axis=0).astype(np.float64), actions.max(axis=0).astype(np.float64)


def candidate_actions(rng: np.random.Generator, count: int, low: np.ndarray | None = None,
                      high: np.ndarray | None = None, n_actions: int | None = None) -> np.ndarray:
    """The K candidates of a step: every action of a discrete space, (n,) int, when
    ``n_actions`` is given; else ``count`` uniform in the box [low, high], (count, d_a)."""
    if n_actions is not None:
        return np.arange(int(n_actions), dtype=np.int64)
    return rng.uniform(low, high, size=(count, len(low)))
