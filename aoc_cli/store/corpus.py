"""A corpus: logged transitions in row order, episodes contiguous.

Shapes (N rows, E episodes, d_o observation dims, d_a action dims):

* ``observations`` (N, d_o) float; ``actions`` (N, d_a) float, or (N,) int64 when discrete;
* ``rewards`` (N,) float64, absent (None) for reward-free data;
* ``terminals``, ``truncations`` (N,) bool; ``timesteps`` (N,) int64, the step within the episode;
* ``episode_starts`` (E + 1,) int64 offsets: episode e is rows ``[starts[e], starts[e+1])``;
* ``tags[name]`` = (codes (N,) int32, labels list[str]): behaviour policy, system, patient group;
* ``columns[name]`` (N,) float64: any other numeric per-row column (usable as a value target);
* ``imputed`` (N, d_o) bool, or None: true where an observation cell was empty in the source
  and filled by the corpus's imputation rule (``preprocessing["impute"]``);
* a table's reader hands over ``observations`` and ``imputed`` as
  :class:`~aoc_cli.store.columns.ColumnStack` (their columns; the writer makes the rows block by
  block); ``np.asarray`` gives the arrays;
* ``preprocessing``: what was fitted while reading (imputation medians and rule, dose-bin
  edges, the split), applied again to data appended or ingested ``--impute-like`` it.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, NamedTuple

import numpy as np

from aoc_cli.errors import AocError, param
from aoc_cli.store.columns import ColumnStack


def box_space(dim: int, low=None, high=None, names: list[str] | None = None) -> dict:
    """A JSON description of a continuous space of ``dim`` dimensions."""
    space: dict[str, Any] = {"type": "box", "shape": [int(dim)]}
    if low is not None:
        space["low"] = np.broadcast_to(np.asarray(low, dtype=float), (dim,)).tolist()
    if high is not None:
        space["high"] = np.broadcast_to(np.asarray(high, dtype=float), (dim,)).tolist()
    if names:
        space["names"] = list(names)
    return space


def discrete_space(n: int, names: list[str] | None = None) -> dict:
    """A JSON description of a discrete space of ``n`` actions."""
    space: dict[str, Any] = {"type": "discrete", "n": int(n)}
    if names:
        space["names"] = list(names)
    return space


def action_labels(space: dict) -> list[str] | None:
    """The label of each discrete action (``names`` holding one entry per action, n > 1: a
    treatment logged as text, icu-sepsis's ``fluids=2,vaso=0``), else None (``names`` of a
    single entry is the action column's name)."""
    names = space.get("names") if space.get("type") == "discrete" else None
    n = int(space.get("n", 0) or 0)
    return [str(x) for x in names] if names and n > 1 and len(names) == n else None


def episode_starts_from_lengths(lengths) -> np.ndarray:
    """Episode lengths (E,) -> offsets (E + 1,)."""
    return np.concatenate([[0], np.cumsum(np.asarray(lengths, dtype=np.int64))]).astype(np.int64)


def all_finite(arr: np.ndarray) -> bool:
    """True when a float array holds no NaN or inf. Fast path: NaN and inf propagate through a
    sum (one pass, no temporary); only when the sum is not finite (a bad value, or an overflow
    of large finite values) is every element checked."""
    if isinstance(arr, ColumnStack):
        return arr.all_finite()
    arr = np.asarray(arr)
    if not np.issubdtype(arr.dtype, np.floating):
        return True
    with np.errstate(over="ignore", invalid="ignore"):
        if np.isfinite(arr.sum()):
            return True
    return bool(np.isfinite(arr).all())


def finite_rows(arr) -> np.ndarray:
    """(N,) bool: the rows of an (N,) or (N, d) array (or a ColumnStack) holding no NaN or
    inf."""
    if isinstance(arr, ColumnStack):
        return arr.finite_rows()
    arr = np.asarray(arr)
    return np.isfinite(arr) if arr.ndim == 1 else np.isfinite(arr).all(axis=1)


@dataclass
class CorpusData:
    """A corpus in memory, as readers produce it and the store writes it."""

    observations: np.ndarray | ColumnStack
    actions: np.ndarray
    rewards: np.ndarray | None
    terminals: np.ndarray
    truncations: np.ndarray
    episode_starts: np.ndarray
    observation_space: dict
    action_space: dict
    tags: dict[str, tuple[np.ndarray, list[str]]] = field(default_factory=dict)
    columns: dict[str, np.ndarray] = field(default_factory=dict)
    episode_ids: list[str] | None = None
    source: dict = field(default_factory=dict)
    imputed: np.ndarray | ColumnStack | None = None
    preprocessing: dict = field(default_factory=dict)

    @property
    def n_rows(self) -> int:
        return int(self.observations.shape[0])

    @property
    def n_episodes(self) -> int:
        return int(len(self.episode_starts) - 1)

    @property
    def discrete(self) -> bool:
        return self.action_space.get("type") == "discrete"

    def timesteps(self) -> np.ndarray:
        """(N,) step index within each episode."""
        lengths = np.diff(self.episode_starts)
        return np.arange(self.n_rows, dtype=np.int64) - np.repeat(self.episode_starts[:-1], lengths)

    def validate(self) -> "CorpusData":
        """Normalise dtypes and check shapes and finiteness; AocError names the first bad row."""
        n = self.n_rows
        if n == 0:
            raise AocError("the data has zero rows: nothing to store")
        if not isinstance(self.observations, ColumnStack):  # a table's columns stay columns
            self.observations = _observation_array(self.observations)
        self.actions = _action_array(self.actions, self.discrete)
        if self.rewards is not None:
            self.rewards = np.asarray(self.rewards, dtype=np.float64).reshape(-1)
        self._check_lengths()
        self.terminals = np.asarray(self.terminals, dtype=bool).reshape(-1)
        self.truncations = np.asarray(self.truncations, dtype=bool).reshape(-1)
        starts = np.asarray(self.episode_starts, dtype=np.int64)
        if starts[0] != 0 or starts[-1] != n or np.any(np.diff(starts) <= 0):
            raise AocError("episode offsets must start at 0, end at the row count and increase")
        self.episode_starts = starts
        self._check_finite()
        self._check_names()
        self.tags = {k: (np.asarray(c, dtype=np.int32), [str(x) for x in lab])
                     for k, (c, lab) in self.tags.items()}
        self.columns = {k: np.asarray(v, dtype=np.float64) for k, v in self.columns.items()}
        if self.imputed is not None:
            if not (isinstance(self.imputed, ColumnStack) and self.imputed.dtype == bool):
                self.imputed = np.asarray(self.imputed, dtype=bool)
            if self.imputed.shape != self.observations.shape:
                raise AocError(f"the imputed mask has shape {self.imputed.shape}, the "
                               f"observations {self.observations.shape}")
        return self

    def _check_lengths(self) -> None:
        """Every per-row array has one entry per row."""
        lengths = {"observations": self.n_rows, "actions": len(self.actions),
                   "terminals": len(self.terminals), "truncations": len(self.truncations)}
        if self.rewards is not None:
            lengths["rewards"] = len(self.rewards)
        for name, (codes, _labels) in self.tags.items():
            lengths[f"tags/{name}"] = len(codes)
        for name, col in self.columns.items():
            lengths[f"columns/{name}"] = len(col)
        if len(set(lengths.values())) != 1:
            raise AocError(
                "arrays of different lengths: "
                + ", ".join(f"{k} has {v}" for k, v in lengths.items())
            )

    def _check_finite(self) -> None:
        """No NaN/inf observation, action or reward; the error names the first such row."""
        for name, arr in (("observations", self.observations), ("actions", self.actions),
                          ("rewards", self.rewards)):
            if arr is None or not np.issubdtype(arr.dtype, np.floating) or all_finite(arr):
                continue
            finite = finite_rows(arr)
            if not finite.all():
                bad = int(np.flatnonzero(~finite)[0])
                raise AocError(
                    f"{name} of row {bad} is not finite (NaN or inf): fix the data or pass "
                    f"{param('drop_nonfinite', True)} to drop the episodes that hold such rows"
                )

    def _check_names(self) -> None:
        """Tag and column names that can be stored as HDF5 dataset names."""
        for kind, names in (("tag", self.tags), ("column", self.columns)):
            for key in names:
                if not isinstance(key, str) or not key.strip() or "/" in key or \
                        key in (".", ".."):
                    raise AocError(f"{kind} name {key!r} cannot be stored: give it a name "
                                   "without '/' (rename the source column)")

    def nonfinite_episodes(self) -> np.ndarray:
        """(E,) bool: episodes holding a NaN/inf observation, action or reward."""
        bad = np.zeros(self.n_rows, dtype=bool)
        for arr in (self.observations, self.actions, self.rewards):
            if arr is None:
                continue
            arr = arr if isinstance(arr, ColumnStack) else np.asarray(arr)
            if not np.issubdtype(arr.dtype, np.floating) or all_finite(arr):
                continue
            bad |= ~finite_rows(arr)
        ep = np.searchsorted(self.episode_starts, np.arange(self.n_rows), side="right") - 1
        out = np.zeros(self.n_episodes, dtype=bool)
        out[ep[bad]] = True
        return out

    def select_episodes(self, keep: np.ndarray) -> "CorpusData":
        """A copy with only the episodes where ``keep`` (E,) is true."""
        keep = np.asarray(keep, dtype=bool)
        lengths = np.diff(self.episode_starts)
        rows = np.repeat(keep, lengths)
        return CorpusData(
            observations=np.asarray(self.observations)[rows],
            actions=np.asarray(self.actions)[rows],
            rewards=None if self.rewards is None else np.asarray(self.rewards)[rows],
            terminals=np.asarray(self.terminals)[rows],
            truncations=np.asarray(self.truncations)[rows],
            episode_starts=episode_starts_from_lengths(lengths[keep]),
            observation_space=self.observation_space,
            action_space=self.action_space,
            tags={k: (np.asarray(c)[rows], lab) for k, (c, lab) in self.tags.items()},
            columns={k: np.asarray(v)[rows] for k, v in self.columns.items()},
            episode_ids=None if self.episode_ids is None
            else [e for e, k in zip(self.episode_ids, keep) if k],
            source=self.source,
            imputed=None if self.imputed is None else np.asarray(self.imputed)[rows],
            preprocessing=self.preprocessing,
        )


class History(NamedTuple):
    """The previous L transitions of each queried row, oldest first, zero-padded at the front.

    observations (R, L, d_o) float32; actions (R, L, d_a) float32, or (R, L) int64 when
    discrete (padding 0); rewards (R, L) float32 (0 for reward-free data); mask (R, L) bool,
    true where a real transition of the same episode is present.
    """

    observations: np.ndarray
    actions: np.ndarray
    rewards: np.ndarray
    mask: np.ndarray


def gather_history(
    rows: np.ndarray,
    episode_start_of_rows: np.ndarray,
    length: int,
    observations: np.ndarray,
    actions: np.ndarray,
    rewards: np.ndarray | None,
) -> History:
    """Histories of ``rows`` (R,) from in-memory arrays; ``episode_start_of_rows`` (R,)."""
    rows = np.asarray(rows, dtype=np.int64)
    r = len(rows)
    if length == 0:
        d_a = () if actions.ndim == 1 else (actions.shape[1],)
        return History(
            np.zeros((r, 0, observations.shape[1]), np.float32),
            np.zeros((r, 0) + d_a, np.int64 if actions.ndim == 1 else np.float32),
            np.zeros((r, 0), np.float32),
            np.zeros((r, 0), bool),
        )
    idx = rows[:, None] - length + np.arange(length)[None, :]  # (R, L), oldest first
    mask = idx >= episode_start_of_rows[:, None]
    safe = np.where(mask, idx, 0)
    obs = observations[safe].astype(np.float32, copy=False)
    obs = obs * mask[..., None]
    act = actions[safe]
    if act.ndim == 3:
        act = act.astype(np.float32, copy=False) * mask[..., None]
    else:
        act = np.where(mask, act, 0).astype(np.int64)
    if rewards is None:
        rew = np.zeros((r, length), np.float32)
    else:
        rew = np.where(mask, rewards[safe], 0.0).astype(np.float32)
    return History(obs, act, rew, mask)


def _float_rows(values, what: str) -> np.ndarray:
    """(N, d) floating rows of ``what`` (a vector is one column; integers become float32)."""
    arr = np.asarray(values)
    if arr.ndim == 1:
        arr = arr[:, None]
    if arr.ndim != 2:
        raise AocError(f"{what} must be (rows, dims), got shape {arr.shape}")
    if not np.issubdtype(arr.dtype, np.floating):
        arr = arr.astype(np.float32)
    return arr


def _observation_array(observations) -> np.ndarray:
    """(N, d_o) observations, floating (integers become float32)."""
    return _float_rows(observations, "observations")


def _action_array(actions, discrete: bool) -> np.ndarray:
    """(N,) int64 discrete actions (whole numbers only) or (N, d_a) floating continuous ones."""
    act = np.asarray(actions)
    if discrete:
        if act.ndim == 2 and act.shape[1] == 1:
            act = act[:, 0]
        if act.ndim != 1:
            raise AocError(f"discrete actions must be one integer per row, got {act.shape}")
        if np.issubdtype(act.dtype, np.floating):
            if not np.all(np.isfinite(act)) or np.any(act != np.round(act)):
                bad = int(np.flatnonzero(~np.isfinite(act) | (act != np.round(act)))[0])
                raise AocError(f"discrete action of row {bad} is not an integer: {act[bad]}")
        return act.astype(np.int64)
    return _float_rows(act, "actions")
