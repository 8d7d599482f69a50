"""Out-of-distribution monitoring: the corpus residual of each chosen action over a rollout.

Two bands: the running band of the episode's own earlier steps (:class:`OODMonitor`, the
default), and a *reference* band per step learned from clean rollouts (:func:`reference_band`,
passed as ``OODMonitor(reference=...)``), which knows that some steps of a task always have a
larger residual (e.g. the maze's hand-over from one expert's rows to another's).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np


@dataclass
class OODMonitor:
    """Flags a step whose residual leaves the running 3-sigma band of the earlier steps.

    The band is mean + ``sigmas`` * std of the residuals of the previous, unflagged steps
    (Welford's running moments), and at least ``minimum``; only the upper side is flagged, since a smaller residual
    means better support. Flagged steps are kept out of the band, so a lasting departure keeps
    being flagged instead of widening the band. No flag during the first ``warmup`` steps.
    """

    warmup: int = 10
    sigmas: float = 3.0
    floor: float = 0.0
    """Smallest std used for the band (so a run of exact zeros does not flag any 1e-9)."""
    minimum: float = 0.0
    """The band never drops below this residual (the corpus's own p99: a residual that 1% of
    the corpus rows reach against the rest is not out of distribution)."""
    reference: np.ndarray | None = None
    """(T,) upper band edge per step from clean rollouts (:func:`reference_band`); when given it
    replaces the running band (no warm-up; steps past its end use its last edge)."""
    n: int = 0
    mean: float = 0.0
    m2: float = 0.0
    flags: list[bool] = field(default_factory=list)
    upper: list[float] = field(default_factory=list)

    @property
    def std(self) -> float:
        return math.sqrt(self.m2 / (self.n - 1)) if self.n > 1 else 0.0

    def band(self) -> float:
        """The current upper edge of the band (inf during warm-up)."""
        if self.reference is not None and len(self.reference):
            return float(self.reference[min(len(self.flags), len(self.reference) - 1)])
        if self.n < max(self.warmup, 2):
            return math.inf
        return max(self.mean + self.sigmas * max(self.std, self.floor), self.minimum)

    def update(self, residual: float) -> bool:
        """Record one step's residual; True when it is flagged out of distribution."""
        edge = self.band()
        self.upper.append(edge)
        flagged = residual > edge
        self.flags.append(bool(flagged))
        if not flagged:
            self.n += 1
            delta = residual - self.mean
            self.mean += delta / self.n
            self.m2 += delta * (residual - self.mean)
        return bool(flagged)


def reference_band(runs, sigmas: float = 3.0, floor: float = 0.0, minimum: float = 0.0,
                   window: int = 2) -> np.ndarray:
    """(T,) upper band edge per step from the residuals of clean rollouts.

    ``runs``: one sequence of per-step residuals per reference episode (None entries, e.g.
    steps of a policy without residuals, are ignored). The edge at step t is mean + ``sigmas``
    x std of every reference residual at steps t - ``window`` .. t + ``window`` (pooled over
    episodes, so a few episodes suffice), the std at least ``floor``, the edge at least
    ``minimum``; T is the longest run.
    """
    lengths = [len(r) for r in runs]
    if not lengths or max(lengths) == 0:
        raise ValueError("reference_band needs at least one reference step")
    T = max(lengths)
    mat = np.full((len(runs), T), np.nan)
    for i, r in enumerate(runs):
        mat[i, :len(r)] = [np.nan if x is None else float(x) for x in r]
    edge = np.empty(T)
    for t in range(T):
        block = mat[:, max(0, t - window):t + window + 1]
        v = block[np.isfinite(block)]
        if len(v) == 0:
            edge[t] = edge[t - 1] if t else math.inf
            continue
        std = float(v.std(ddof=1)) if len(v) > 1 else 0.0
        edge[t] = max(float(v.mean()) + sigmas * max(std, floor), minimum)
    return edge


def flags_against(residuals, band: np.ndarray) -> np.ndarray:
    """(T,) bool: which steps' residuals exceed ``band`` (steps past its end: its last edge)."""
    r = np.array([np.nan if x is None else float(x) for x in residuals], dtype=float)
    edges = np.asarray(band, dtype=float)[np.minimum(np.arange(len(r)), len(band) - 1)]
    return np.nan_to_num(r, nan=-math.inf) > edges


def band_limits(session) -> tuple[float, float]:
    """(floor of the std, minimum edge) of the OOD bands: 0.1 x the corpus's typical p50
    residual and its p99 (see :class:`OODMonitor`) of a session (model-free: none)."""
    index = getattr(session, "index", None)
    if index is None:  # a model-free session: no band limits
        return 0.0, 0.0
    typical = index.typical
    return 0.1 * (typical.p50 or 0.0), typical.p99 or 0.0
