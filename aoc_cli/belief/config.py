"""The belief model's configuration, with the paper's defaults.

Paper: "Accountability in Offline Reinforcement Learning: Explaining Decisions with a Corpus
of Examples", section "Optimization Procedure"
(its first equation), appendix "Learning the Belief Space" (hyper-parameter table) and appendix
"The Strictly Batch (Offline) Imitation Setting" (reward-free data).
"""

from __future__ import annotations

import os
from dataclasses import asdict, dataclass, fields

from aoc_cli.errors import AocError, BadSetting, param

MODES = ("value", "imitation")
#: What the value-mode belief b(o, a, h) is trained on (the linear head always maps it to the
#: chosen value v): ``value`` (the paper's text: regress v), ``critic`` (the last hidden layer of
#: an offline Q-learning critic, as the paper's reference code), ``reward`` (a model of the
#: immediate reward, the reference code's "mb" variant), ``dynamics`` (regress v and, through an
#: auxiliary head, the change of observation o' - o).
BELIEFS = ("value", "critic", "reward", "dynamics")
#: The dynamics weight ``--belief dynamics`` implies when none is given.
DEFAULT_DYNAMICS_WEIGHT = 1.0
#: ``--belief critic`` when ``critic_steps`` is not given (BeliefConfig.critic_steps_for):
#: CRITIC_STEPS at CRITIC_STEPS_ROWS rows and above, proportionally fewer below, at least
#: CRITIC_STEPS_MIN.
CRITIC_STEPS = 10_000
CRITIC_STEPS_ROWS = 100_000
CRITIC_STEPS_MIN = 500
#: Seconds a critic step takes on one CPU thread at batch 500 (measured here: ~0.07-0.1 s);
#: ``aoc train`` shows the estimate up front.
CRITIC_STEP_SECONDS = 0.08
#: Value targets computed from the rewards; any other name is a numeric corpus column.
REWARD_TARGETS = ("return", "mean-return", "reward", "fqe")


@dataclass
class BeliefConfig:
    r"""How to learn the belief function b and the linear head l.

    Value mode (AOC), the paper's equation (algo_1)::

        b, l = argmin_{b, l}  E_{(o, a, h, v) in D} ( v - l(b(o, a, h)) )^2

    with v standardised, ``b(o, a, h) = act(W3 relu(W2 relu(W1 [GRU(h), o, a])))`` in R^{d_b}
    (three fully connected layers; the last activated layer is the belief) and ``l`` linear.
    Imitation mode (ABC, strictly batch imitation, for reward-free data)::

        b, l = argmin_{b, l}  E_{(o, a, h) in D}  loss(a, l(b(o, h)))

    with ``loss`` the squared error on standardised actions (continuous) or the cross-entropy
    of the logits ``l(b)`` (discrete). ``h`` is the previous ``history_length`` transitions
    (o, a, r) of the same episode, zero-padded at the episode start, with the mask as an input
    feature; ``history_length = 0`` drops the GRU and b depends on (o, a) (or o) alone.

    Defaults from the paper's table: GRU, 128 hidden units, 1 recurrent layer, batch 500, Adam,
    learning rate 0.001, memory length 4, embedding (belief) dimension 20. The paper trains
    4000 epochs; aoc stops early on the validation loss instead (``patience``, ``max_epochs``).
    """

    mode: str = "value"
    #: What the value-mode belief is trained on: one of BELIEFS (see there; aoc_cli.belief.kinds).
    belief: str = "value"
    #: ``return`` (discounted return-to-go), ``mean-return``, ``reward`` or a column name.
    value: str = "return"
    gamma: float = 0.99
    history_length: int = 4
    belief_dim: int = 20
    #: Units of the GRU (one layer) and of the first two fully connected layers.
    hidden: int = 128
    #: Value mode: weight of the auxiliary loss that makes b(o, a, h) also predict the change of
    #: observation o' - o through a second linear head (0 = the paper's objective exactly).
    dynamics_weight: float = 0.0
    #: ``critic``: gradient steps of the offline critic (TD3+BC, aoc_cli.belief.critic); None:
    #: :meth:`critic_steps_for` (10,000 at 100k rows and above, what the bench's full scale
    #: trains and docs/results.md measures: pendulum-het upright at 100k -0.051, lunar at 0.3M
    #: 265.8; fewer on a smaller corpus, and at most ``max_epochs`` passes over the training
    #: rows). The resolved count is what the saved model's config records.
    critic_steps: int | None = None
    #: ``critic``: weight of the behaviour-cloning term in the actor's loss (TD3+BC's 1 / alpha;
    #: 0 = plain TD3 as the reference code; see aoc_cli/belief/critic.py).
    critic_bc_weight: float = 0.4
    #: Activation of the belief layer: ``tanh`` (bounded, no dead units) or ``relu``.
    belief_activation: str = "tanh"
    lr: float = 1e-3
    #: L2 penalty of Adam (0: the paper's objective; ``aoc train`` may choose one on small
    #: corpora, aoc_cli.belief.select).
    weight_decay: float = 0.0
    #: Imitation, discrete actions: ``none`` or ``balanced`` (each action's cross-entropy
    #: weighted by N / (n_actions * N_action) over the corpus rows, so a rare action counts as
    #: much as a common one). The validation loss stays the plain cross-entropy.
    class_weight: str = "none"
    #: Imitation, discrete actions: label smoothing of the training cross-entropy (0: none).
    label_smoothing: float = 0.0
    #: Dropout after each of the two hidden fully connected layers (0: none, the paper's).
    dropout: float = 0.0
    batch_size: int = 500
    max_epochs: int = 200
    #: Stop after this many epochs without a validation-loss improvement of ``min_delta``.
    patience: int = 10
    min_delta: float = 1e-4
    #: Share of the episodes held out for validation (split by episode, never by row).
    val_fraction: float = 0.2
    seed: int = 0
    #: CPU threads for torch; ``None`` = every core this process may use.
    threads: int | None = None
    #: ``auto`` (a GPU when torch sees one, else CPU), ``cpu`` or ``cuda``.
    device: str = "auto"

    def __post_init__(self):
        # ``dynamics`` is the value belief with the auxiliary head: either spelling names it
        # (a model saved before --belief existed records only the weight).
        if self.belief == "value" and self.mode == "value" and self.dynamics_weight > 0:
            self.belief = "dynamics"
        elif self.belief == "dynamics" and self.dynamics_weight == 0:
            self.dynamics_weight = DEFAULT_DYNAMICS_WEIGHT

    def validate(self) -> "BeliefConfig":
        """Check every field; a :class:`BadSetting` names the setting to fix."""
        if self.mode not in MODES:
            raise BadSetting("mode", self.mode, f"unknown {param('mode')} {self.mode!r}: use value "
                             "or imitation")
        if self.belief not in BELIEFS:
            raise BadSetting("belief", self.belief, f"unknown {param('belief')} {self.belief!r}: "
                             f"use {', '.join(BELIEFS)}")
        if self.dynamics_weight > 0 and self.belief in ("critic", "reward"):
            raise BadSetting("dynamics_weight", self.dynamics_weight,
                             f"{param('dynamics_weight')} belongs to {param('belief', 'dynamics')}"
                             f", not {param('belief', self.belief)}")
        if self.critic_steps is not None and self.critic_steps < 1:
            raise BadSetting("critic_steps", self.critic_steps,
                             f"{param('critic_steps')} must be >= 1, got {self.critic_steps}")
        if not self.critic_bc_weight >= 0:
            raise BadSetting("critic_bc_weight", self.critic_bc_weight,
                             f"{param('critic_bc_weight')} must be >= 0, got "
                             f"{self.critic_bc_weight}")
        if not self.value:
            raise BadSetting("value", self.value, f"{param('value')} is empty: use return, "
                             "mean-return, reward or a column name")
        if self.history_length < 0:
            raise BadSetting("history_length", self.history_length,
                             f"{param('history_length')} must be >= 0, got {self.history_length}")
        if not 0.0 <= self.gamma <= 1.0:
            raise BadSetting("gamma", self.gamma,
                             f"{param('gamma')} must be in [0, 1], got {self.gamma}")
        for name in ("belief_dim", "hidden", "batch_size", "max_epochs"):
            if getattr(self, name) < 1:
                raise BadSetting(name, getattr(self, name),
                                 f"{param(name)} must be >= 1, got {getattr(self, name)}")
        if not self.dynamics_weight >= 0:
            raise BadSetting("dynamics_weight", self.dynamics_weight,
                             f"{param('dynamics_weight')} must be >= 0, got {self.dynamics_weight}")
        if self.dynamics_weight > 0 and self.mode != "value":
            raise BadSetting("dynamics_weight", self.dynamics_weight,
                             f"{param('dynamics_weight')} needs {param('mode', 'value')} (the "
                             "imitation belief b(o, h) has no action to predict the next "
                             "observation from)")
        if self.belief != "value" and self.mode != "value":
            raise BadSetting("belief", self.belief,
                             f"{param('belief', self.belief)} needs {param('mode', 'value')} "
                             "(the imitation belief is trained on the logged action)")
        if self.patience < 1:
            raise BadSetting("patience", self.patience,
                             f"{param('patience')} must be >= 1, got {self.patience}")
        if not self.weight_decay >= 0:
            raise BadSetting("weight_decay", self.weight_decay,
                             f"{param('weight_decay')} must be >= 0, got {self.weight_decay}")
        if self.class_weight not in ("none", "balanced"):
            raise BadSetting("class_weight", self.class_weight,
                             f"unknown {param('class_weight')} {self.class_weight!r}: use none "
                             "or balanced")
        if not 0.0 <= self.label_smoothing < 1.0:
            raise BadSetting("label_smoothing", self.label_smoothing,
                             f"{param('label_smoothing')} must be in [0, 1), got "
                             f"{self.label_smoothing}")
        if not 0.0 <= self.dropout < 1.0:
            raise BadSetting("dropout", self.dropout,
                             f"{param('dropout')} must be in [0, 1), got {self.dropout}")
        if not self.lr > 0:
            raise BadSetting("lr", self.lr,
                             f"{param('lr')} must be > 0, got {self.lr}")
        if not 0.0 < self.val_fraction < 1.0:
            raise BadSetting("val_fraction", self.val_fraction,
                             f"{param('val_fraction')} must be in (0, 1), got {self.val_fraction}")
        if self.threads is not None and self.threads < 1:
            raise BadSetting("threads", self.threads,
                             f"{param('threads')} must be >= 1, got {self.threads}")
        if self.belief_activation not in ("tanh", "relu"):
            raise BadSetting("belief_activation", self.belief_activation,
                             f"unknown belief activation {self.belief_activation!r}: "
                             "use tanh or relu")
        if self.device not in ("auto", "cpu", "cuda"):
            raise BadSetting("device", self.device,
                             f"unknown device {self.device!r}: use auto, cpu or cuda")
        return self

    def critic_steps_for(self, n_rows: int, n_train_rows: int) -> tuple[int, str]:
        """The critic's gradient steps on a corpus of ``n_rows`` rows (``n_train_rows`` of them
        in training episodes), and the rule that gave them, as a phrase.

        Given (``critic_steps``): exactly that. Else :data:`CRITIC_STEPS` x n_rows /
        :data:`CRITIC_STEPS_ROWS` (one step per 10 rows), between :data:`CRITIC_STEPS_MIN` and
        :data:`CRITIC_STEPS`, and at most ``max_epochs`` passes over the training rows in
        batches of ``batch_size`` (``--epochs`` bounds the critic as it bounds every belief).
        """
        if self.critic_steps is not None:
            return int(self.critic_steps), "--critic-steps"
        by_rows = min(CRITIC_STEPS, max(CRITIC_STEPS_MIN,
                                        -(-CRITIC_STEPS * int(n_rows) // CRITIC_STEPS_ROWS)))
        per_epoch = max(1, -(-int(n_train_rows) // int(self.batch_size)))
        by_epochs = int(self.max_epochs) * per_epoch
        if by_epochs < by_rows:
            return by_epochs, (f"{self.max_epochs} epochs of {per_epoch} batches of the "
                               f"{n_train_rows} training rows")
        return by_rows, (f"one step per {CRITIC_STEPS_ROWS // CRITIC_STEPS} rows of the "
                         f"{n_rows:,}, at least {CRITIC_STEPS_MIN} and at most "
                         f"{CRITIC_STEPS:,}")

    def resolved_threads(self) -> int:
        """The explicit CPU thread count torch will use."""
        if self.threads is not None:
            return int(self.threads)
        try:
            return max(1, len(os.sched_getaffinity(0)))
        except AttributeError:  # pragma: no cover - not Linux
            return max(1, os.cpu_count() or 1)

    def to_dict(self) -> dict:
        return asdict(self)

    @classmethod
    def from_dict(cls, data: dict, strict: bool = True) -> "BeliefConfig":
        """The config of ``data``'s settings. ``strict``: a key that is no setting is an
        AocError; False (a saved model's config, which may hold an older aoc's keys) ignores
        it."""
        known = {f.name for f in fields(cls)}
        unknown = sorted(set(data) - known)
        if strict and unknown:
            raise AocError(f"unknown belief setting {unknown[0]!r}: the settings are "
                           f"{', '.join(sorted(known))}")
        return cls(**{k: v for k, v in data.items() if k in known})


@dataclass(frozen=True)
class FQEConfig:
    """Fitted Q evaluation's settings (recorded in the model's ``config.json`` value spec;
    ``--value fqe``, :mod:`aoc_cli.belief.fqe`)."""

    iterations: int = 30
    """Backups: values reach this many steps back from an episode's end."""
    steps: int = 300
    """Gradient steps per backup (at least two epochs of the distinct inputs)."""
    hidden: int = 128
    batch_size: int = 1024
    lr: float = 3e-3
    final_lr: float = 3e-4
    """Learning rate of the last ``final_iterations`` backups (the values settle)."""
    final_iterations: int = 3
    seed: int = 0

    def to_dict(self) -> dict:
        return asdict(self)
