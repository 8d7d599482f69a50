"""Out-of-distribution monitoring: the corpus residual of each chosen action over a rollout."""

from __future__ import annotations

import math
from dataclasses import dataclass, field


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
