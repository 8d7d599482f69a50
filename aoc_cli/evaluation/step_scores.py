"""The per-step results of a scored chunk of held-out episodes (:class:`StepScores`): what
:mod:`aoc_cli.evaluation.score` computes and merges and :mod:`aoc_cli.evaluation.records`
writes, one record per step."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np


@dataclass
class StepScores:
    """Per-step results of a chunk (S steps), all arrays with S rows.

    ``row`` held-out rows; ``episode``, ``step``; ``logged`` (S,) int or (S, d_a);
    ``decided`` likewise; ``scores`` (S, n) action weights (discrete imitation) or None;
    ``v_hat`` / ``target`` (S,) value mode (v_hat of the logged action; the target is set
    by the driver after the chunks merge, :meth:`EvalContext.targets`), ``decided_value``
    (S,) v_hat of the decision; ``residual`` (S,) of the decision; ``warning``
    (S,) bool heterogeneity; ``support_rows``/``support_weights`` (S, m) (-1 / 0 padded);
    ``baselines`` name -> {"decided", "scores" or "v_hat"} arrays on the same steps.
    """

    row: np.ndarray
    episode: np.ndarray
    step: np.ndarray
    logged: np.ndarray
    decided: np.ndarray
    residual: np.ndarray
    warning: np.ndarray
    support_rows: np.ndarray
    support_weights: np.ndarray
    scores: np.ndarray | None = None
    v_hat: np.ndarray | None = None
    target: np.ndarray | None = None
    baselines: dict = field(default_factory=dict)
    decided_value: np.ndarray | None = None
