"""Step 4's candidate filter (docs/design.md, "The method, precisely"): keep the candidates
whose corpus residual is within the epsilon-quantile of the K residuals and, with a residual cap
c, within c x the corpus's typical p90 residual. One rule for the controller
(:meth:`aoc_cli.control.Controller.candidate_filter`, one step) and ``aoc evaluate`` (every
held-out step at once)."""

from __future__ import annotations

import numpy as np


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
