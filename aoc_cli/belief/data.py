"""What training is fed, checked before torch is imported (so bad input fails at once):
the model folder, the value targets and the validation split by episode."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from aoc_cli.belief.config import BeliefConfig
from aoc_cli.belief.targets import value_targets
from aoc_cli.errors import AocError
from aoc_cli.store import check_name


def model_dir(corpus, model_id: str) -> Path:
    """``<corpus>/models/<model_id>/``."""
    return Path(corpus.models_dir) / check_name(model_id, "model")


def split_episodes(n_episodes: int, val_fraction: float, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """(train episodes, validation episodes), sorted; at least one episode in each."""
    if n_episodes < 2:
        raise AocError(
            f"the corpus has {n_episodes} episode(s): a validation split by episode needs at "
            "least 2; collect or ingest more episodes"
        )
    n_val = min(n_episodes - 1, max(1, int(round(n_episodes * val_fraction))))
    perm = np.random.default_rng(seed).permutation(n_episodes)
    return np.sort(perm[n_val:]), np.sort(perm[:n_val])


def episode_rows(episode_starts: np.ndarray, episodes: np.ndarray) -> np.ndarray:
    """(R,) int64 rows of the given episodes, in row order."""
    episodes = np.asarray(episodes, dtype=np.int64)
    starts = episode_starts[episodes]
    lengths = episode_starts[episodes + 1] - starts
    offsets = np.arange(lengths.sum()) - np.repeat(np.cumsum(lengths) - lengths, lengths)
    return (np.repeat(starts, lengths) + offsets).astype(np.int64)


@dataclass
class TrainingData:
    """values (N,) float64 in value mode (else None); train/validation rows (R,) int64."""

    values: np.ndarray | None
    train_episodes: np.ndarray
    val_episodes: np.ndarray
    train_rows: np.ndarray
    val_rows: np.ndarray


def prepare(corpus, config: BeliefConfig, model_id: str, overwrite: bool) -> TrainingData:
    """Check the request (config, model id, value target, split) and compute the targets."""
    config.validate()
    if model_dir(corpus, model_id).exists() and not overwrite:
        raise AocError(f"model {model_id!r} of corpus {corpus.name!r} already exists: pass "
                       "--overwrite to replace it, or choose another --model")
    values = value_targets(corpus, config.value, config.gamma) if config.mode == "value" else None
    train_eps, val_eps = split_episodes(corpus.n_episodes, config.val_fraction, config.seed)
    starts = corpus.episode_starts
    return TrainingData(values, train_eps, val_eps, episode_rows(starts, train_eps),
                        episode_rows(starts, val_eps))
