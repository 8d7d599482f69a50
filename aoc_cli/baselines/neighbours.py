"""The paper's nearest-neighbour controllers (1NN and kNN), on raw features or on beliefs.

Nearest-neighbour Q-estimation (Shah and Xie 2018, the paper's "1NN" and "kNN"): each of the K
candidate actions a (the same candidates as AOC: uniform in a box, every action of a discrete
space) gets the value of its k nearest corpus rows,

    v_hat(a) = (1 / k) sum_{c in N_k(x(o, a, h))} v^c,          pi(o, h) = argmax_a v_hat(a),

with no residual filter (no epsilon) and no hull: the neighbours are averaged whether or not
they surround the query. ``x`` is either the raw feature map of
:mod:`aoc_cli.baselines.features` (standardised o, a, flattened history) or the AOC belief
``b(o, a, h)``, searched in the session's own index. ``v^c`` is the value target of the AOC
session's model (the same v as AOC). k = 1 for 1NN; kNN uses :func:`knn_k` (the controller's
k, else the paper's 2 (d_b + 1)).
"""

from __future__ import annotations

import numpy as np

from aoc_cli.baselines.common import ActionSpace, corpus_values
from aoc_cli.baselines.features import RawFeatures
from aoc_cli.decompose import default_k
from aoc_cli.index.search import BeliefIndex, IndexConfig


def knn_k(session) -> int:
    """kNN's k: the controller's ``config.k`` when set (``--k``), else the paper's
    k = 2 (d_b + 1) -- the k rule without the index's own widening for imitation of discrete
    actions (:func:`aoc_cli.decompose.default_k` with no rarest-action share), as the paper
    runs Shah and Xie's kNN."""
    k = session.controller.config.k
    return int(k) if k is not None else default_k(session.model.d_b)


class NearestNeighbourController:
    """argmax over the K candidates of the mean value of their k nearest corpus rows.

    ``space`` is ``"raw"`` (standardised o, a, flattened history; a FAISS index over the
    corpus's feature rows) or ``"belief"`` (the session's belief model and index). The corpus
    rows are those of the session's index (a re-sampled index repeats rows) and its row
    selection.
    """

    def __init__(self, session, env=None, k: int = 1, space: str = "raw", seed: int = 0,
                 name: str | None = None):
        self.session = session
        self.k = int(k)
        self.space = space
        self.name = name or f"{k}nn-{space}"
        self.actions = ActionSpace(session, env)
        self.values = corpus_values(session, self.name)
        self.candidates = int(session.controller.config.candidates)
        self.rng = np.random.default_rng(seed)
        ci = session.index
        self.rows = np.asarray(ci.rows, np.int64)          # index position -> corpus row
        selection = session.controller.selection
        self.position_mask = None if selection is None else np.asarray(selection, bool)[self.rows]
        if space == "raw":
            self.features = RawFeatures.fit(session.corpus, session.model.history_length)
            feats = self.features.corpus_features(session.corpus)
            self.index = BeliefIndex.build(np.ascontiguousarray(feats[self.rows]),
                                           IndexConfig(threads=1))
        elif space == "belief":
            self.features = None
            self.index = ci.index
        else:
            raise ValueError(f"unknown neighbour space {space!r}")
        self.selector = None if self.position_mask is None else \
            self.index.select(self.position_mask)
        self.seed = seed

    def reset(self) -> None:
        pass

    def embed(self, observation: np.ndarray, candidates: np.ndarray, history) -> np.ndarray:
        """(K, D) raw features or (K, d_b) beliefs of the K candidates."""
        n = len(candidates)
        obs = np.repeat(np.asarray(observation, np.float32).reshape(1, -1), n, axis=0)
        if self.space == "raw":
            return self.features.transform(obs, candidates, history)
        # the one-row history is shared by the K candidates (the GRU runs once)
        return self.session.model.beliefs(obs, candidates, history)

    def estimate(self, observation, candidates, history) -> tuple[np.ndarray, np.ndarray]:
        """(K,) value estimates and (K, k) corpus rows of the candidates' neighbours."""
        queries = np.ascontiguousarray(self.embed(observation, candidates, history), np.float32)
        _dist, pos = self.index.search(queries, self.k, selection=self.selector)
        valid = pos >= 0
        rows = np.where(valid, self.rows[np.maximum(pos, 0)], -1)
        vals = np.where(valid, self.values[np.maximum(rows, 0)], 0.0)
        value = vals.sum(axis=1) / np.maximum(valid.sum(axis=1), 1)
        return value, rows

    def decide(self, observation, history):
        candidates = self.actions.candidates(self.rng, self.candidates)
        value, _rows = self.estimate(observation, candidates, history)
        return self.actions.clip(candidates[int(np.argmax(value))])
