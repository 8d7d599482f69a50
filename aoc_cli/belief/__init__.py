"""The belief function b and the linear head l (value mode: AOC; imitation mode: ABC).

>>> from aoc_cli.belief import BeliefConfig, train_model, load_model
>>> metrics = train_model(corpus, BeliefConfig(), "default")     # doctest: +SKIP
>>> model = load_model(corpus)                                    # doctest: +SKIP
>>> b = model.row_beliefs(corpus)            # (N, d_b) float32   # doctest: +SKIP

Names are imported lazily, so that importing the config (as every CLI start does) does not
import torch.

Threads: training sets torch's threads (``BeliefConfig.threads``) for its own duration only;
the ``aoc`` command makes OpenMP threads wait passively (:mod:`aoc_cli.threads`).
"""

from __future__ import annotations

from aoc_cli.lazy import exports

_WHERE = {
    "BeliefConfig": "config",
    "BeliefModel": "artefact",
    "LinearHead": "artefact",
    "check_corpus": "artefact",
    "list_models": "artefact",
    "load_model": "artefact",
    "logistic_probe": "probe",
    "discounted_return_to_go": "targets",
    "mean_remaining_reward": "targets",
    "value_targets": "targets",
    "split_episodes": "data",
    "episode_rows": "data",
    "prepare": "data",
    "train_model": "train",
    "FQEConfig": "fqe",
    "fitted_q_values": "fqe",
    "default_row_smoothing": "row_labels",
    "subset_scores": "row_labels",
}

__all__ = sorted(_WHERE)


__getattr__, __dir__ = exports(__name__, _WHERE)
