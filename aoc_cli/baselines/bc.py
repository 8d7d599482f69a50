"""Behaviour cloning with the same history encoder as AOC.

The BC policy is the head of an imitation-mode belief model trained on the same corpus
(``aoc train NAME --model bc --mode imitation``): the same GRU over the history and three fully
connected layers, with a linear head trained to predict the corpus action,

    l, b = argmin E_{(o, a, h) in D} || a - l(b(o, h)) ||^2     (continuous)
    l, b = argmin E_{(o, a, h) in D} CE(a, l(b(o, h)))          (discrete: argmax of the logits)

At control time the action is the head's prediction (clipped to the action box). This is the
paper's "BC" baseline: a black box with the AOC network, without the corpus decomposition.
"""

from __future__ import annotations

import numpy as np

from aoc_cli.baselines.common import ActionSpace
from aoc_cli.errors import AocError, ModelMissing, call, param

BC_MODEL = "bc"


def load_bc_model(corpus, model_id: str = BC_MODEL):
    """The imitation-mode model ``model_id`` of ``corpus``, or AocError saying how to train it."""
    from aoc_cli.belief import list_models, load_model  # lazy: torch, for the bc model only

    if model_id not in list_models(corpus):
        raise ModelMissing(corpus.name, model_id, list_models(corpus), mode="imitation",
                           why=f"the bc baseline needs an imitation-mode model {model_id!r} of "
                               f"corpus {corpus.name!r}")
    model = load_model(corpus, model_id)
    if model.mode != "imitation":
        fix = call("train", corpus.name, model=model_id, mode="imitation", overwrite=True)
        raise AocError(f"model {model_id!r} of corpus {corpus.name!r} is a {model.mode}-mode "
                       f"model; the bc baseline needs `{fix}`")
    return model


class BehaviourCloning:
    """The action predicted by an imitation-mode belief model (module docstring)."""

    name = "bc"

    def __init__(self, session, env=None, seed: int = 0, model=None, model_id: str = BC_MODEL):
        self.actions = ActionSpace(session, env)
        self.model = model if model is not None else load_bc_model(session.corpus, model_id)
        if self.model.history_length > session.model.history_length:
            raise AocError(f"the bc model uses a history of {self.model.history_length} steps, "
                           f"longer than the session's {session.model.history_length}: train "
                           f"it with the same {param('history_length')}")

    def decide(self, observation, history):
        obs = np.asarray(observation, np.float32).reshape(1, -1)
        out = np.asarray(self.model.predict(obs, None, history))[0]
        if self.actions.discrete:
            return int(np.argmax(out))
        return self.actions.clip(out)
