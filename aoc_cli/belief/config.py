"""The belief model's configuration, with the paper's defaults.

Paper: "Accountability in Offline Reinforcement Learning: Explaining Decisions with a Corpus
of Examples", section "Optimization Procedure"
(its first equation), appendix "Learning the Belief Space" (hyper-parameter table) and appendix
"The Strictly Batch (Offline) Imitation Setting" (reward-free data).
"""

from __future__ import annotations

from dataclasses import dataclass

from aoc_cli.errors import BadSetting, param
from aoc_cli.settings import Settings, setting
from aoc_cli.threads import cores

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
REWARD_TARGETS = ("return", "mean-return", "reward", "fqe", "neighbours")


@dataclass(frozen=True)
class BeliefConfig(Settings):
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

    label = "belief"

    mode: str = setting("value", choices=MODES,
                        help="value: b(o, a, h) predicts v (AOC); imitation: b(o, h) predicts "
                             "the action (ABC, reward-free data).")
    #: What the value-mode belief is trained on: one of BELIEFS (see there; aoc_cli.belief.kinds).
    belief: str = setting("value", choices=BELIEFS,
                          help="Value mode: what the belief is trained on: value (regress the "
                               "value target), critic (an offline TD3+BC critic's last hidden "
                               "layer), reward (a model of the immediate reward) or dynamics "
                               "(value + the o' - o head). The linear head maps every belief "
                               "to the value target.")
    #: ``return`` (discounted return-to-go), ``mean-return``, ``reward`` or a column name.
    value: str = setting("return", help="Value target: return (discounted return-to-go), "
                                        "mean-return, reward, fqe (the behaviour's Q by fitted "
                                        "Q evaluation, bootstrapped through the log), "
                                        "neighbours (the same with the mean of the log's rows "
                                        "near an observation as the regressor), or a numeric "
                                        "corpus column.")
    gamma: float = setting(0.99, bounds="[0, 1]",
                           help="Discount of the value targets return, fqe and neighbours.")
    history_length: int = setting(4, bounds=">= 0",
                                  help="Previous transitions of the episode the GRU reads "
                                       "(0: no history).")
    belief_dim: int = setting(20, bounds=">= 1", help="Belief dimension d_b.")
    #: Units of the GRU (one layer) and of the first two fully connected layers.
    hidden: int = setting(128, bounds=">= 1", help="Units of the GRU and hidden layers.")
    #: Value mode: weight of the auxiliary loss that makes b(o, a, h) also predict the change of
    #: observation o' - o through a second linear head (0 = the paper's objective exactly).
    dynamics_weight: float = setting(0.0, bounds=">= 0",
                                     help="Value mode: weight of the auxiliary loss that makes "
                                          "the belief also predict o' - o (0: the paper's "
                                          "objective alone; the dynamics belief: "
                                          f"{DEFAULT_DYNAMICS_WEIGHT:g} unless given).")
    #: ``critic``: gradient steps of the offline critic (TD3+BC, aoc_cli.belief.critic); None:
    #: :meth:`critic_steps_for` (10,000 at 100k rows and above, what the bench's full scale
    #: trains and docs/results/ measures: pendulum-het upright at 100k -0.051, lunar at 0.3M
    #: 265.8; fewer on a smaller corpus, and at most ``max_epochs`` passes over the training
    #: rows). The resolved count is what the saved model's config records.
    critic_steps: int | None = setting(
        None, bounds=">= 1", help="The critic belief: gradient steps.",
        none=f"one per {CRITIC_STEPS_ROWS // CRITIC_STEPS} rows, between {CRITIC_STEPS_MIN} "
             f"and {CRITIC_STEPS:,}, at most max_epochs passes over the training rows")
    #: ``critic``: weight of the behaviour-cloning term in the actor's loss (TD3+BC's 1 / alpha;
    #: 0 = plain TD3 as the reference code; see aoc_cli/belief/critic.py).
    critic_bc_weight: float = setting(0.4, bounds=">= 0",
                                      help="The critic belief: weight of the actor's "
                                           "behaviour-cloning term (0: plain TD3).")
    belief_activation: str = setting("tanh", choices=("tanh", "relu"),
                                     help="Activation of the belief layer: tanh (bounded, no "
                                          "dead units) or relu.")
    lr: float = setting(1e-3, bounds="> 0", help="Adam learning rate.")
    #: L2 penalty of Adam (0: the paper's objective; ``aoc train`` may choose one on small
    #: corpora, aoc_cli.training.tuning).
    weight_decay: float = setting(0.0, bounds=">= 0", help="Adam's L2 penalty.")
    #: Imitation, discrete actions: ``balanced`` weighs each action's cross-entropy by
    #: N / (n_actions * N_action) over the corpus rows, so a rare action counts as much as a
    #: common one. The validation loss stays the plain cross-entropy.
    class_weight: str = setting("none", choices=("none", "balanced"),
                                help="Imitation, discrete actions: none, or balanced (each "
                                     "action's loss weighted by its rarity).")
    label_smoothing: float = setting(0.0, bounds="[0, 1)",
                                     help="Imitation, discrete actions: label smoothing of the "
                                          "training loss (0: none, the paper's).")
    dropout: float = setting(0.0, bounds="[0, 1)",
                             help="Dropout after the two hidden layers while training (0: "
                                  "none, the paper's).")
    batch_size: int = setting(500, bounds=">= 1", help="Mini-batch rows.")
    max_epochs: int = setting(200, bounds=">= 1",
                              help="Maximum epochs (early stopping ends sooner; the critic "
                                   "belief: at most this many passes over the training rows).")
    patience: int = setting(10, bounds=">= 1",
                            help="Stop after this many epochs without a better validation "
                                 "loss.")
    min_delta: float = setting(1e-4, bounds=">= 0",
                               help="The smallest decrease of the validation loss that counts "
                                    "as better.")
    #: Split by episode, never by row.
    val_fraction: float = setting(0.2, bounds="(0, 1)",
                                  help="Share of episodes held out for validation.")
    seed: int = setting(0, help="Seed of the split, initialisation and batches (reproducible "
                                "on CPU).")
    threads: int | None = setting(None, bounds=">= 1", help="CPU threads (torch's, FAISS's and "
                                  "numpy's) for all of training.",
                                  none="every core this process may use")
    device: str = setting("auto", choices=("auto", "cpu", "cuda"),
                          help="auto (a GPU when torch sees one, else CPU), cpu or cuda.")

    def __post_init__(self):
        # ``dynamics`` is the value belief with the auxiliary head: either spelling names it
        # (a model saved before --belief existed records only the weight).
        if self.belief == "value" and self.mode == "value" and self.dynamics_weight > 0:
            object.__setattr__(self, "belief", "dynamics")
        elif self.belief == "dynamics" and self.dynamics_weight == 0:
            object.__setattr__(self, "dynamics_weight", DEFAULT_DYNAMICS_WEIGHT)
        super().__post_init__()

    def check(self) -> "BeliefConfig":
        """Check every field, then the fields together; a :class:`BadSetting` names the
        setting to fix."""
        super().check()
        if self.dynamics_weight > 0 and self.belief in ("critic", "reward"):
            raise BadSetting("dynamics_weight", self.dynamics_weight,
                             f"{param('dynamics_weight')} belongs to {param('belief', 'dynamics')}"
                             f", not {param('belief', self.belief)}")
        if not self.value:
            raise BadSetting("value", self.value, f"{param('value')} is empty: use return, "
                             "mean-return, reward or a column name")
        if self.dynamics_weight > 0 and self.mode != "value":
            raise BadSetting("dynamics_weight", self.dynamics_weight,
                             f"{param('dynamics_weight')} needs {param('mode', 'value')} (the "
                             "imitation belief b(o, h) has no action to predict the next "
                             "observation from)")
        if self.belief != "value" and self.mode != "value":
            raise BadSetting("belief", self.belief,
                             f"{param('belief', self.belief)} needs {param('mode', 'value')} "
                             "(the imitation belief is trained on the logged action)")
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
        return int(self.threads) if self.threads is not None else cores()


@dataclass(frozen=True)
class FQEConfig(Settings):
    """Fitted Q evaluation's settings (recorded in the model's ``config.json`` value spec;
    ``--value fqe``, :mod:`aoc_cli.belief.fqe`)."""

    label = "fitted Q evaluation"

    # 60 (was 30): on a 10k-episode icu-sepsis log (p99 episode length 47, cycles through
    # repeated states) 30 backups left the values short of the fixed point; chosen by held-out
    # returns-to-go (docs/notes/results-icu-sepsis.md, "FQE to its fixed point").
    iterations: int = setting(60, bounds=">= 1", help="Backups: values reach this many steps "
                                                      "back from an episode's end.")
    steps: int = setting(300, bounds=">= 1", help="Gradient steps per backup (at least two "
                                                  "epochs of the distinct inputs).")
    hidden: int = setting(128, bounds=">= 1", help="Units of each hidden layer of the MLP.")
    batch_size: int = setting(1024, bounds=">= 1", help="Mini-batch rows.")
    lr: float = setting(3e-3, bounds="> 0", help="Learning rate.")
    final_lr: float = setting(3e-4, bounds="> 0", help="Learning rate of the last "
                                                       "final_iterations backups (the values "
                                                       "settle).")
    final_iterations: int = setting(3, bounds=">= 0", help="Backups at final_lr.")
    seed: int = setting(0, help="Seed of the initialisation and batches.")
    # "expected" (was the logged next row's): the same where no observation repeats; where they
    # do, it shares out the noise of which action one patient happened to take next (expected
    # SARSA; docs/results/icu-sepsis.md).
    next_value: str = setting("expected", choices=("expected", "logged"),
                              help="A target's value of the next step: Q(o', a) averaged over "
                                   "every row of the log at o' (expected), or the next row's "
                                   "own Q(o', a') (logged).")
