"""The belief function b and the linear head l (value mode: AOC; imitation mode: ABC).

>>> from aoc_cli.belief import BeliefConfig, train_model, load_model
>>> metrics = train_model(corpus, BeliefConfig(), "default")     # doctest: +SKIP
>>> model = load_model(corpus)                                    # doctest: +SKIP
>>> b = model.row_beliefs(corpus)            # (N, d_b) float32   # doctest: +SKIP
"""

from aoc_cli.belief.artefact import BeliefModel, LinearHead, check_corpus, list_models, load_model
from aoc_cli.belief.config import BeliefConfig
from aoc_cli.belief.probe import logistic_probe
from aoc_cli.belief.targets import discounted_return_to_go, mean_remaining_reward, value_targets
from aoc_cli.belief.train import split_episodes, train_model

__all__ = [
    "BeliefConfig",
    "BeliefModel",
    "LinearHead",
    "check_corpus",
    "discounted_return_to_go",
    "list_models",
    "load_model",
    "logistic_probe",
    "mean_remaining_reward",
    "split_episodes",
    "train_model",
    "value_targets",
]
