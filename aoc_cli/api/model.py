"""The API's entries that build on a corpus: train (the belief model), build_index."""

from __future__ import annotations

from dataclasses import dataclass

from aoc_cli.api.common import Log, StoreLike, open_store
from aoc_cli.belief.config import BeliefConfig
from aoc_cli.training.evidence import CONTROLLER
from aoc_cli.training.fit import Trained, check_settings, train_corpus
from aoc_cli.control.config import ControllerConfig, ControllerLike, given_settings
from aoc_cli.index import CorpusIndex
from aoc_cli.index import build_index as _build_index
from aoc_cli.errors import BadSetting, param
from aoc_cli.progress import Progress
from aoc_cli.store import DEFAULT_INDEX, DEFAULT_MODEL

_D = BeliefConfig()  # the paper's settings: the defaults of train()


def train(name: str, *, store: StoreLike = None, model: str = DEFAULT_MODEL,
          mode: str | None = None, belief: str | None = None, value: str | None = None,
          gamma: float | None = None, history_length: int | None = None,
          dynamics_weight: float | None = None, hidden: int | None = None,
          weight_decay: float | None = None, label_smoothing: float | None = None,
          belief_dim: int = _D.belief_dim, max_epochs: int = _D.max_epochs,
          batch_size: int = _D.batch_size, lr: float = _D.lr, patience: int = _D.patience,
          val_fraction: float = _D.val_fraction, seed: int = _D.seed,
          threads: int | None = None, dropout: float = _D.dropout,
          class_weight: str = _D.class_weight, critic_steps: int | None = None,
          critic_bc_weight: float = _D.critic_bc_weight, device: str = _D.device,
          paper: bool = False, no_select: bool = False,
          overwrite: bool = False, progress: Progress | None = None,
          log: Log | None = None, controller: ControllerLike = None) -> Trained:
    """Train the belief model ``model`` of corpus ``name`` (``aoc train``): ``mode`` value
    (AOC: b(o, a, h) predicts ``value``) or imitation (ABC: b(o, h) predicts the action).
    Settings left None are decided from the log's evidence (:mod:`aoc_cli.training.evidence`:
    rewards or none, discrete actions, the episodes' lengths, how often observations recur),
    then chosen by validation on a small log (history_length, hidden, weight_decay), else the
    paper's; ``paper``: the paper's for all; ``no_select``: no choice by validation. The
    controller settings the evidence decides are saved with the model. The other arguments are :class:`~aoc_cli.belief.BeliefConfig`'s
    (``belief_dim`` d_b, ``max_epochs``, ``device`` auto|cpu|cuda, ...). One writer per
    model id; ``overwrite`` replaces one. ``controller``: controller settings to save with the
    model (a mapping or ControllerConfig of epsilon, residual_cap, support_penalty, k; None
    values: decided), instead of those the evidence decides or the validation episodes
    choose (:mod:`aoc_cli.training.controller_selection`). Returns
    :class:`~aoc_cli.training.fit.Trained` (``.metrics`` as saved)."""
    settings = dict(mode=mode, belief=belief, value=value, gamma=gamma,
                    history_length=history_length, dynamics_weight=dynamics_weight,
                    hidden=hidden, weight_decay=weight_decay, label_smoothing=label_smoothing,
                    belief_dim=belief_dim, max_epochs=max_epochs, batch_size=batch_size, lr=lr,
                    patience=patience, val_fraction=val_fraction, seed=seed, threads=threads,
                    dropout=dropout, class_weight=class_weight, critic_steps=critic_steps,
                    critic_bc_weight=critic_bc_weight, device=device)
    check_settings(settings)  # bad settings fail before the store is read
    given = controller_given(controller)
    corpus = open_store(store).corpus(name)
    return train_corpus(corpus, model, paper=paper, select_settings=not no_select,
                        overwrite=overwrite, progress=progress, log=log, controller=given,
                        choose_controller=True, **settings)


def controller_given(controller: ControllerLike) -> dict:
    """The controller settings ``train`` saves as given: checked as ControllerConfig's, and
    only those training records (:data:`aoc_cli.training.evidence.CONTROLLER`)."""
    given = given_settings(controller)
    if isinstance(controller, ControllerConfig):  # a whole config: its recorded fields only
        given = {k: v for k, v in given.items() if k in CONTROLLER}
    other = sorted(set(given) - set(CONTROLLER))
    if other:
        raise BadSetting(other[0], given[other[0]],
                         f"train saves only the controller settings {', '.join(CONTROLLER)} "
                         f"with the model, not {param(other[0])}: give it when deciding")
    ControllerConfig(**given)  # bounds checked
    return given


@dataclass
class Indexed:
    """An index built: the corpus's name and the :class:`~aoc_cli.index.CorpusIndex`."""

    corpus: str
    index: CorpusIndex

    def summary(self) -> dict:
        """What ``aoc index`` prints."""
        meta = self.index.meta
        return {"corpus": self.corpus, "model": meta["model"], "index": meta["index_id"],
                "kind": meta["kind"], "rows": meta["rows"], "belief_dim": meta["belief_dim"],
                "k": meta["k"], "candidates": meta["candidates"],
                "typical_residual": self.index.typical_residual,
                "build_seconds": meta["build_seconds"]}


def build_index(name: str, model: str | None = None, *, store: StoreLike = None,
                kind: str = "auto", index_id: str = DEFAULT_INDEX,
                episode_rates: dict[str, float] | None = None,
                subsample: dict[str, float] | None = None, seed: int = 0,
                neighbours: str = "auto", progress: Progress | None = None) -> Indexed:
    """Compute every row's belief under ``model`` (default 'default', else the latest) and
    build the index (``kind`` auto|flat|hnsw|ivf) the controller searches. ``episode_rates``
    {"TAG=VALUE": rate} derive an index ``index_id`` that repeats (rate > 1) or keeps a random
    share (rate < 1) of those episodes; ``subsample``: rates of at most 1, the older form.
    ``neighbours``: step 1's neighbour rows, auto|nearest|per_action."""
    corpus = open_store(store).corpus(name)
    for key, rate in (subsample or {}).items():
        if rate > 1:
            raise BadSetting("subsample", rate, f"{param('subsample')} rates are <= 1 (got "
                             f"{rate} for {key}); use {param('episode_rates')}")
    ci = _build_index(corpus, model, kind=kind, index_id=index_id,
                      episode_rates={**(subsample or {}), **(episode_rates or {})}, seed=seed,
                      progress=progress, candidates=neighbours)
    return Indexed(corpus.name, ci)
