"""What training is fed, checked before torch is imported (so bad input fails at once):
the model folder, the value targets and the validation split by episode."""

from __future__ import annotations

import copy
import math
import time
from dataclasses import dataclass

import numpy as np

from aoc_cli.belief.config import BeliefConfig
from aoc_cli.belief.targets import neighbourhood_targets, value_targets
from aoc_cli.errors import AocError, ModelExists
from aoc_cli.store import model_dir


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


def episode_folds(n_episodes: int, val_fraction: float, seed: int,
                  folds: int) -> list[tuple[np.ndarray, np.ndarray]]:
    """Up to ``folds`` (train episodes, validation episodes) splits, sorted, for choosing
    settings by cross-validation: the validation episodes are disjoint blocks of the usual
    size (:func:`split_episodes`'s) taken in order from the same random order of the
    episodes, so the first fold is :func:`split_episodes`'s split; as many as there are whole
    blocks of episodes."""
    _train, first = split_episodes(n_episodes, val_fraction, seed)  # checks n_episodes
    n_val = len(first)
    order = np.random.default_rng(seed).permutation(n_episodes)
    return [(np.sort(np.concatenate([order[:j * n_val], order[(j + 1) * n_val:]])),
             np.sort(order[j * n_val:(j + 1) * n_val]))
            for j in range(max(1, min(folds, n_episodes // n_val)))]


def episode_rows(episode_starts: np.ndarray, episodes: np.ndarray) -> np.ndarray:
    """(R,) int64 rows of the given episodes, in row order."""
    episodes = np.asarray(episodes, dtype=np.int64)
    starts = episode_starts[episodes]
    lengths = episode_starts[episodes + 1] - starts
    offsets = np.arange(lengths.sum()) - np.repeat(np.cumsum(lengths) - lengths, lengths)
    return (np.repeat(starts, lengths) + offsets).astype(np.int64)


@dataclass
class TrainingData:
    """values (N,) float64 in value mode (else None); train/validation rows (R,) int64;
    ``neighbourhood`` (N,) float64 rule 7's values of the rows, saved with the model
    (:func:`aoc_cli.index.search.neighbourhood.neighbourhood_values`), or None; ``space``
    what its sets were built from (:meth:`~aoc_cli.index.search.neighbourhood.Neighbourhood.
    space`), saved with them."""

    values: np.ndarray | None
    train_episodes: np.ndarray
    val_episodes: np.ndarray
    train_rows: np.ndarray
    val_rows: np.ndarray
    neighbourhood: np.ndarray | None = None
    space: dict | None = None


def prepare(corpus, config: BeliefConfig, model_id: str, overwrite: bool,
            progress=None) -> TrainingData:
    """Check the request (config, model id, value target, split) and compute the targets;
    ``progress`` follows a target that takes a while (``fqe``'s backups)."""
    if model_dir(corpus.path, model_id).exists() and not overwrite:
        raise ModelExists(corpus.name, model_id)
    values = hood = space = None
    if config.mode == "value" and config.value == "neighbours" and corpus.has_rewards:
        # the belief's targets and rule 7's one-step values, from one FQE
        values, hood, space = neighbourhood_targets(corpus, config.gamma, progress=progress)
    elif config.mode == "value":
        values = value_targets(corpus, config.value, config.gamma, progress=progress)
    train_eps, val_eps = split_episodes(corpus.n_episodes, config.val_fraction, config.seed)
    starts = corpus.episode_starts
    return TrainingData(values, train_eps, val_eps, episode_rows(starts, train_eps),
                        episode_rows(starts, val_eps), hood, space)


class EarlyStopping:
    """The training loop's bookkeeping, shared by the in-memory and the streamed loops: one
    record per epoch, the best epoch's weights, and the stopping rule (the validation loss has
    not improved by more than ``min_delta`` for ``patience`` epochs, or is not finite)."""

    def __init__(self, net, config: BeliefConfig, started: float):
        self.config, self.started = config, started
        self.history: list[dict] = []
        self.best = {"val_loss": math.inf, "epoch": 0, "state": copy.deepcopy(net.state_dict())}
        self.stale = 0

    def running(self, epoch: int, batch: int, batches: int, train_loss: float) -> dict:
        """The progress record of a batch inside an epoch."""
        return {"epoch": epoch, "max_epochs": self.config.max_epochs, "batch": batch,
                "batches": batches, "train_loss": train_loss,
                "val_loss": self.history[-1]["val_loss"] if self.history else None,
                "best_val_loss": None if self.best["epoch"] == 0 else self.best["val_loss"],
                "epoch_done": False}

    def end_epoch(self, net, epoch: int, train_loss: float, val: dict, batches: int) -> dict:
        """Record the epoch (val: the validation metrics, ``loss`` first), keep the weights if
        they are the best so far; returns the epoch's progress record."""
        record = {"epoch": epoch, "train_loss": train_loss, "val_loss": val["loss"]}
        record.update({f"val_{k}": v for k, v in val.items() if k != "loss"})
        record["seconds"] = time.perf_counter() - self.started
        self.history.append(record)
        if val["loss"] < self.best["val_loss"] - self.config.min_delta:
            self.best = {"val_loss": val["loss"], "epoch": epoch,
                         "state": copy.deepcopy(net.state_dict())}
            self.stale = 0
        else:
            self.stale += 1
        return {**record, "max_epochs": self.config.max_epochs, "batch": batches,
                "batches": batches, "best_val_loss": self.best["val_loss"], "epoch_done": True}

    @property
    def done(self) -> bool:
        last = self.history[-1]["val_loss"] if self.history else 0.0
        return self.stale >= self.config.patience or not math.isfinite(last)


def report(progress, record: dict, unit: str = "epoch") -> None:
    """Report a training record (:meth:`EarlyStopping.running` / ``end_epoch``) to
    ``progress`` (:mod:`aoc_cli.progress`): the epochs (or steps) done of the most, labelled
    with the batch and the losses."""
    if progress is None:
        return
    val, best = record["val_loss"], record["best_val_loss"]
    label = (f"{unit} {record['epoch']} batch {record['batch']}/{record['batches']} "
             f"train {record['train_loss']:.4f}"
             + ("" if val is None else f" val {val:.4f}")
             + ("" if best is None else f" best {best:.4f}"))
    progress(record["epoch"] - (0 if record["epoch_done"] else 1), record["max_epochs"], label)
