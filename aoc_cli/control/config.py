"""The controller's settings, with the paper's defaults; a model carries its own
(:meth:`ControllerConfig.for_model`)."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

from aoc_cli.errors import BadSetting, param
from aoc_cli.settings import Settings, given_fields, setting


@dataclass(frozen=True)
class ControllerConfig(Settings):
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
    action of the minimal corpus subset of :math:`b(o_t, h_t)` (discrete: the argmax of the
    actions' scores over its rows, ``row_smoothing``; aoc_cli.belief.row_labels).
    """

    label = "controller"

    candidates: int = setting(100, bounds=">= 1",
                              help="K, candidate actions per step (a discrete space uses every "
                                   "action).")
    epsilon: float = setting(0.5, bounds="(0, 1]",
                             help="Keep the candidates whose residual is within this quantile "
                                  "of the K residuals.")
    residual_cap: float | None = setting(
        None, bounds="> 0", none="no cap",
        help="c: also drop candidates whose residual exceeds c times the corpus's typical p90 "
             "residual (ignored for an index built without a typical residual).")
    #: None: no minimum (the paper's rule); none has m: the best supported of those that pass
    #: the residual filter.
    min_support: float | None = setting(
        None, bounds=">= 1", none="no minimum",
        help="Value mode: m, also drop candidates whose value is backed by fewer than m "
             "distinct episodes (the support, aoc_cli.control.support).")
    #: sigma_v the std of the corpus values (aoc_cli.control.support.penalised).
    support_penalty: float | None = setting(
        None, bounds=">= 0", none="rank by v_hat",
        help="Value mode: z, rank the candidates that pass by v_hat - z sigma_v / "
             "sqrt(support), a value shrunk by how many episodes back it.")
    #: Rule 7 (docs/design.md, "Settings from the log's evidence"): None is on for a
    #: value-mode model of discrete actions (aoc_cli.index.search.neighbourhood).
    do_no_harm: str | None = setting(
        None, choices=("on", "off"),
        none="on (value mode, discrete actions), unless rule 2's exact-repeat bound ranks "
             "the actions (a support penalty)",
        help="Value mode, discrete actions: keep the clinicians' likely action unless another "
             "action's lower bound over the log's rows near the step beats its own (on), or "
             "rank by v_hat alone (off).")
    #: The index's ``k``: ``index.json``, set by the k rule when it was built
    #: (aoc_cli.decompose.k_rule).
    k: int | None = setting(
        None, bounds=">= 1",
        none="the index's: 2 (d_b + 1); an imitation model of discrete actions: at least "
             "(d_b + 1) / the rarest action's share, up to 16 (d_b + 1)",
        help="Nearest corpus beliefs per query.")
    sampler: str = setting("uniform", choices=("uniform", "bc"),
                           help="Candidates: uniform in the action box, or bc (a "
                                "behaviour-cloning model + noise).")
    bc_model: str = setting("bc", help="Model id of the imitation-mode model the bc sampler "
                                       "uses.")
    bc_noise: float = setting(0.2, bounds=">= 0",
                              help="Standard deviation of the bc sampler's noise, as a "
                                   "fraction of the action range.")
    #: None: :func:`aoc_cli.belief.row_labels.default_row_smoothing` (0.75 for discrete
    #: imitation with the candidates of every action, else 0).
    row_smoothing: float | None = setting(
        None, bounds="[0, 1]",
        none="0.75 for discrete imitation with the candidates of every action, else 0",
        help="Imitation: lambda, each named row's label is its logged action smoothed by "
             "lambda towards the belief's probabilities at that row; an action's score is "
             "the subset's weighted sum of the labels (0: the action's weight).")
    min_weight: float = setting(0.05, bounds=">= 0",
                                help="Supporting rows with at least this weight count when "
                                     "checking for disagreement.")
    action_spread: float = setting(0.5, bounds=">= 0",
                                   help="Heterogeneity warning: supporting actions spread "
                                        "more than this fraction of the range.")
    value_spread: float = setting(1.0, bounds=">= 0",
                                  help="Heterogeneity warning: supporting values spread more "
                                       "than this many corpus value stds.")
    ood_warmup: int = setting(10, bounds=">= 0",
                              help="Steps before the OOD monitor starts flagging.")
    ood_sigmas: float = setting(3.0, bounds="> 0",
                                help="A step is flagged when its residual exceeds the running "
                                     "mean by this many stds.")

    @classmethod
    def for_model(cls, saved: Mapping | None = None, **given) -> "ControllerConfig":
        """The settings of a decision with a model: those ``given`` (None: not given) over the
        settings saved with the model (``saved``: its config's ``metrics.controller``, decided
        by ``aoc train`` from the log's evidence, aoc_cli.training.evidence) over the paper's
        defaults. A model trained without them (by the library's ``train_model``, or before
        they were recorded) has none: the paper's."""
        # the model's k reaches the controller through its index, built with it (an index
        # built with another --neighbours rule keeps the k that fits it)
        settings = {k: v for k, v in (saved or {}).items()
                    if k in cls.__dataclass_fields__ and k != "k"}
        settings.update({k: v for k, v in given.items() if v is not None})
        return cls(**settings)


#: ``controller=`` of the API's deciding entries (open_session, rollout, explain, evaluate,
#: bench): a ControllerConfig, a mapping of its fields, or None (no setting given).
ControllerLike = ControllerConfig | Mapping | None


def given_settings(controller: ControllerLike) -> dict:
    """The controller settings ``controller`` gives, {field: value}: a ControllerConfig's or a
    mapping's fields that are not None (None: not given, so the model's setting, else the
    paper's default, applies when :meth:`ControllerConfig.for_model` resolves them). A key that
    is no field of ControllerConfig is a :class:`~aoc_cli.errors.BadSetting` naming it and
    the known ones; the values are checked when the config is built."""
    if controller is None:
        return {}
    if isinstance(controller, ControllerConfig):
        return {k: v for k, v in controller.to_dict().items() if v is not None}
    if not isinstance(controller, Mapping):
        raise BadSetting("controller", controller,
                         f"{param('controller')} must be a ControllerConfig or a mapping of its "
                         f"settings, got {type(controller).__name__}")
    return given_fields(ControllerConfig, controller, "controller")
