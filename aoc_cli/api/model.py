"""The API's entries that build on a corpus: train (the belief model), build_index."""

from __future__ import annotations

import warnings
from collections.abc import Mapping
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
from aoc_cli.settings import given_fields
from aoc_cli.store import DEFAULT_INDEX, DEFAULT_MODEL

#: train()'s flat keyword arguments of BeliefConfig's fields, kept for a release: give them
#: as ``belief={...}`` (or a BeliefConfig) instead.
FLAT = ("mode", "value", "gamma", "history_length", "dynamics_weight", "hidden", "weight_decay",
        "label_smoothing", "belief_dim", "max_epochs", "batch_size", "lr", "patience",
        "val_fraction", "seed", "threads", "dropout", "class_weight", "critic_steps",
        "critic_bc_weight", "device")
BeliefLike = BeliefConfig | Mapping | str | None


def train(name: str, *, store: StoreLike = None, model: str = DEFAULT_MODEL,
          belief: BeliefLike = None, controller: ControllerLike = None,
          paper: bool = False, no_select: bool = False, overwrite: bool = False,
          progress: Progress | None = None, log: Log | None = None,
          mode: str | None = None, value: str | None = None, gamma: float | None = None,
          history_length: int | None = None, dynamics_weight: float | None = None,
          hidden: int | None = None, weight_decay: float | None = None,
          label_smoothing: float | None = None, belief_dim: int | None = None,
          max_epochs: int | None = None, batch_size: int | None = None, lr: float | None = None,
          patience: int | None = None, val_fraction: float | None = None,
          seed: int | None = None, threads: int | None = None, dropout: float | None = None,
          class_weight: str | None = None, critic_steps: int | None = None,
          critic_bc_weight: float | None = None, device: str | None = None) -> Trained:
    """Train the belief model ``model`` of corpus ``name`` (``aoc train``). ``belief``: the
    belief's settings, as ``controller=`` takes the controller's: a mapping of
    :class:`~aoc_cli.belief.BeliefConfig`'s fields (``{"mode": "imitation", "max_epochs":
    20}``: the settings given), a BeliefConfig (taken whole: every field given, the evidence
    decides none of them), or a string, the belief's kind (value, critic, reward, dynamics;
    as before). ``mode`` value (AOC: b(o, a, h) predicts ``value``) or imitation (ABC: b(o,
    h) predicts the action). Settings not given are decided from the log's evidence
    (:mod:`aoc_cli.training.evidence`: rewards or none, discrete actions, the episodes'
    lengths, how often observations recur), then chosen by validation on a small log
    (history_length, hidden, weight_decay), else the paper's; ``paper``: the paper's for all;
    ``no_select``: no choice by validation. The controller settings the evidence decides are
    saved with the model. One writer per model id; ``overwrite`` replaces one.
    ``controller``: controller settings to save with the model (a mapping or ControllerConfig
    of epsilon, residual_cap, support_penalty, k; None values: decided), instead of those the
    evidence decides or the validation episodes choose
    (:mod:`aoc_cli.training.controller_selection`). The flat keyword arguments (``mode=``,
    ``max_epochs=``, ...) still work for this release, with a DeprecationWarning. Returns
    :class:`~aoc_cli.training.fit.Trained` (``.metrics`` as saved)."""
    flat = {k: v for k, v in dict(
        mode=mode, value=value, gamma=gamma, history_length=history_length,
        dynamics_weight=dynamics_weight, hidden=hidden, weight_decay=weight_decay,
        label_smoothing=label_smoothing, belief_dim=belief_dim, max_epochs=max_epochs,
        batch_size=batch_size, lr=lr, patience=patience, val_fraction=val_fraction, seed=seed,
        threads=threads, dropout=dropout, class_weight=class_weight,
        critic_steps=critic_steps, critic_bc_weight=critic_bc_weight,
        device=device).items() if v is not None}
    if flat:
        warnings.warn(f"train({', '.join(f'{k}=' for k in flat)}): give the belief's settings "
                      f"as belief={{{', '.join(repr(k) + ': ...' for k in flat)}}} (or a "
                      "BeliefConfig); the flat keyword arguments go in a later release",
                      DeprecationWarning, stacklevel=2)
    settings = {**flat, **belief_given(belief, flat)}
    check_settings(settings)  # bad settings fail before the store is read
    given = controller_given(controller)
    corpus = open_store(store).corpus(name)
    return train_corpus(corpus, model, paper=paper, select_settings=not no_select,
                        overwrite=overwrite, progress=progress, log=log, controller=given,
                        choose_controller=True, **settings)


def belief_given(belief: BeliefLike, flat: dict | None = None) -> dict:
    """The belief settings ``belief`` gives, {field: value}: a string is the belief's kind; a
    BeliefConfig's every field; a mapping's fields that are not None. A key that is no field
    of BeliefConfig, or one given twice (here and as a flat keyword argument), is a
    BadSetting."""
    if belief is None:
        return {}
    if isinstance(belief, str):
        return {"belief": belief}
    if isinstance(belief, BeliefConfig):
        given = belief.to_dict()
    elif isinstance(belief, Mapping):
        given = given_fields(BeliefConfig, belief, "belief")
    else:
        raise BadSetting("belief", belief, f"{param('belief')} must be a BeliefConfig, a "
                         f"mapping of its settings or the belief's kind, got "
                         f"{type(belief).__name__}")
    twice = sorted(set(given) & set(flat or {}))
    if twice:
        raise BadSetting(twice[0], given[twice[0]], f"{param(twice[0])} is given twice: in "
                         f"{param('belief')} and as a keyword argument")
    return given


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
