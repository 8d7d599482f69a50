"""The controller's settings, with the paper's defaults."""

from __future__ import annotations

from dataclasses import asdict, dataclass

from aoc_cli.envs import TASKS
from aoc_cli.errors import AocError


@dataclass
class ControllerConfig:
    r"""Algorithm 1 of the paper (the Accountable Offline Controller).

    At each step, K candidate actions :math:`a^{(1..K)}` are sampled; each gets a belief
    :math:`b_t = b(o_t, a, h_t)`, a corpus residual :math:`r(b_t)` and a value estimate
    :math:`\hat v(a) = \sum_c w^c v^c` over its minimal corpus subset. The decision is

    .. math:: \pi(o_t, h_t) = \arg\max_{a:\ r(a) \le q_\epsilon(r)} \hat v(a)

    where :math:`q_\epsilon` is the epsilon-quantile of the K residuals (ties: the smaller
    residual). With ``residual_cap`` c set, the threshold is also capped by the corpus's own
    typical residual (the paper's absolute form, :math:`r \le \epsilon`, in corpus units):

    .. math:: \tau = \min(q_\epsilon(r),\ c\, r_{90}),

    :math:`r_{90}` the 90th percentile of the residuals of held-out corpus rows decomposed
    against the other rows (``index.json`` ``typical_residual.p90``); when no candidate has
    :math:`r \le \tau`, the smallest-residual candidate is kept. With ``min_support`` m, a
    candidate must also be backed by at least m distinct episodes (its support, the effective
    number of episodes behind its v_hat; :mod:`aoc_cli.control.support`); with
    ``support_penalty`` z the argmax is of v_hat - z sigma_v / sqrt(support). In imitation mode
    (ABC) there are no candidates: the decision is the weighted
    action of the minimal corpus subset of :math:`b(o_t, h_t)`.
    """

    candidates: int = 100
    """K, candidate actions per step (a discrete space uses every action)."""
    epsilon: float = 0.5
    """Keep candidates whose residual is within this quantile of the K residuals, in (0, 1]."""
    residual_cap: float | None = None
    """c: also drop candidates whose residual exceeds c x the corpus's typical p90 residual
    (None: no cap; ignored for an index built without ``typical_residual``)."""
    min_support: float | None = None
    """m: also drop candidates whose value is backed by fewer than m distinct episodes (the
    support, :mod:`aoc_cli.control.support`); none has m: the best supported of those that
    pass the residual filter. None: no minimum (the paper's rule)."""
    support_penalty: float | None = None
    """z: rank the candidates that pass by v_hat - z sigma_v / sqrt(support) (sigma_v the std
    of the corpus values; aoc_cli.control.support.penalised) instead of v_hat. None: v_hat."""
    k: int | None = None
    """Nearest corpus beliefs per query; None = the index's (``index.json`` ``k``, set by the k
    rule when it was built: aoc_cli.decompose.k_rule)."""
    sampler: str = "uniform"
    """uniform (in a box action space) | bc (a behaviour-cloning model plus Gaussian noise)."""
    bc_model: str = "bc"
    """Model id of the imitation-mode model used by the bc sampler."""
    bc_noise: float = 0.2
    """Standard deviation of the bc sampler's noise, as a fraction of the action range."""
    min_weight: float = 0.05
    """Supporting rows with at least this weight count when checking for disagreement."""
    action_spread: float = 0.5
    """Heterogeneity warning: supporting actions spread more than this fraction of the range."""
    value_spread: float = 1.0
    """Heterogeneity warning: supporting values spread more than this many corpus value stds."""
    ood_warmup: int = 10
    """Steps before the OOD monitor starts flagging."""
    ood_sigmas: float = 3.0
    """A step is flagged when its residual exceeds the running mean by this many stds."""

    @classmethod
    def for_task(cls, task: str | None, **flags) -> "ControllerConfig":
        """The settings for ``task``: the ``flags`` given (None: not given) over the built-in
        task's own settings (``Task.controller``; none for another name, an ingested corpus's
        ``""`` or None) over the paper's defaults; checked."""
        settings = dict(getattr(TASKS.get(task), "controller", None) or {}) if task else {}
        settings.update({k: v for k, v in flags.items() if v is not None})
        return cls(**settings).check()

    def check(self) -> "ControllerConfig":
        if not 0.0 < self.epsilon <= 1.0:
            raise AocError(f"epsilon must be in (0, 1], got {self.epsilon}", "epsilon")
        if self.candidates < 1:
            raise AocError(f"candidates must be >= 1, got {self.candidates}", "candidates")
        if self.residual_cap is not None and not self.residual_cap > 0:
            raise AocError(f"residual_cap must be > 0, got {self.residual_cap}", "residual_cap")
        if self.min_support is not None and not self.min_support >= 1:
            raise AocError(f"min_support must be >= 1 episode, got {self.min_support}",
                           "min_support")
        if self.support_penalty is not None and not self.support_penalty >= 0:
            raise AocError(f"support_penalty must be >= 0, got {self.support_penalty}",
                           "support_penalty")
        if self.k is not None and self.k < 1:
            raise AocError(f"k must be >= 1, got {self.k}", "k")
        if self.sampler not in ("uniform", "bc"):
            raise AocError(f"sampler {self.sampler!r} is unknown: use uniform or bc", "sampler")
        return self

    def to_dict(self) -> dict:
        return asdict(self)
