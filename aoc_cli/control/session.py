"""The session: a corpus with its belief model, corpus index and controller, ready to act
(:func:`open_session`), or a corpus alone for the policies that need no model
(:func:`model_free_session`)."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from aoc_cli.control.config import ControllerConfig
from aoc_cli.control.controller import Controller
from aoc_cli import belief
from aoc_cli.index import CorpusIndex, load_index
from aoc_cli.errors import AocError, call, param, warn
from aoc_cli.store import DEFAULT_INDEX, Corpus

if TYPE_CHECKING:
    from aoc_cli.belief.artefact import BeliefModel


@dataclass
class Session:
    """A controller ready to act: corpus, belief model, index (with its row values) and the
    controller over them (its settings and row selection). ``action_space``: the
    environment's, when it is narrower than the corpus's."""

    corpus: Corpus
    model: BeliefModel
    index: CorpusIndex
    controller: Controller
    action_space: dict | None = None

    @property
    def history_length(self) -> int:
        """L of the model: the previous transitions a belief reads."""
        return int(self.model.history_length)

    def meta(self) -> dict:
        """What an audit log records of the session."""
        selection = self.controller.selection
        return {
            "corpus": self.corpus.name, "corpus_hash": self.corpus.hash,
            "model": self.model.id, "model_hash": self.model.hash,
            "index": self.index.index_id, "mode": self.model.mode,
            "config": self.controller.config.to_dict(),
            "selection": None if selection is None
            else np.flatnonzero(selection).tolist() if selection.sum() < 10000 else "mask",
        }


@dataclass
class ModelFreeSession:
    """A corpus without model or index, for the policies that need neither (zero, random):
    they run on a corpus before anything is trained."""

    corpus: Corpus
    action_space: dict | None = None

    @property
    def history_length(self) -> int:
        """0: a model-free policy reads no history."""
        return 0

    def meta(self) -> dict:
        return {"corpus": self.corpus.name, "corpus_hash": self.corpus.hash, "model": None}


def open_session(corpus: Corpus, model_id: str | None = None, index_id: str = DEFAULT_INDEX,
                 config: ControllerConfig | Mapping | None = None,
                 selection: np.ndarray | None = None, seed: int = 0,
                 action_space: dict | None = None) -> Session:
    """Load the model and index of ``corpus`` and build a controller; ``selection`` an (N,)
    bool row mask (:func:`aoc_cli.rows.row_selection`). ``config``: a
    :class:`ControllerConfig` is taken whole; a mapping holds the settings given, laid over
    the settings saved with the model (:meth:`ControllerConfig.for_model`); None: the
    model's."""
    index = load_index(corpus, model_id, index_id)
    if not isinstance(config, ControllerConfig):
        config = ControllerConfig.for_model(model_controller(index.model), **(config or {}))
    if config.row_smoothing is not None and not (index.model.mode == "imitation"
                                                  and corpus.discrete):
        warn(f"{param('row_smoothing')} applies to ABC's scores (imitation of discrete "
             f"actions); the {index.model.mode}-mode model of corpus {corpus.name!r} does not "
             "use it")
    bc_model = None
    if config.sampler == "bc" and index.model.mode == "value" and not corpus.discrete:
        bc_model = belief.load_model(corpus, config.bc_model)  # torch, loaded here
        if bc_model.mode != "imitation":
            raise AocError(f"model {config.bc_model!r} is not an imitation-mode model: the bc "
                           "sampler needs "
                           f"`{call('train', corpus.name, model=config.bc_model, mode='imitation')}`")
    controller = Controller(corpus, index, config, selection=selection, bc_model=bc_model,
                            seed=seed, action_space=action_space)
    return Session(corpus, index.model, index, controller, action_space)


def model_controller(model) -> dict:
    """The controller settings saved with ``model`` (a BeliefModel): decided by ``aoc train``
    (``metrics.controller`` of its config.json); {} when none were recorded."""
    return dict((model.meta.get("metrics") or {}).get("controller") or {})


def model_free_session(corpus: Corpus, action_space: dict | None = None) -> ModelFreeSession:
    """A session for the zero and random policies: no model or index is opened."""
    return ModelFreeSession(corpus, action_space)
