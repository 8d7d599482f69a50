"""What every reader shares: options, HDF5 opening with clear errors, flat (D4RL-style) arrays
to episodes, label encoding of tag columns, and the length check.

Readers return a :class:`aoc_cli.store.CorpusData`; the rows of an episode are (o_t, a_t, r_t),
the observation at which action a_t was taken and the reward that followed it.
"""

from __future__ import annotations

import contextlib
import warnings
from dataclasses import dataclass, field
from pathlib import Path
from typing import Iterator

import h5py
import numpy as np

from aoc_cli.errors import AocError, param, warn
from aoc_cli.progress import Progress
from aoc_cli.store import CorpusData, box_space, discrete_space, episode_starts_from_lengths
from aoc_cli.store.corpus import all_finite


@dataclass
class ReadOptions:
    """How to read a dataset (the flags of ``aoc ingest``).

    ``progress`` (:mod:`aoc_cli.progress`): the chunks or episodes read by slow loops.
    The CSV fields are ignored by the other readers.
    """

    tags: dict[str, str] = field(default_factory=dict)
    tag_columns: list[str] = field(default_factory=list)
    reward_free: bool = False
    drop_nonfinite: bool = False
    discrete_actions: bool = False
    # CSV only
    columns_file: Path | None = None
    obs_columns: list[str] | None = None
    act_columns: list[str] | None = None
    reward_column: str | None = None
    id_column: str | None = None
    time_column: str | None = None
    terminal_column: str | None = None
    static: Path | None = None
    progress: Progress | None = None
    # clinical tables (CSV, Parquet, frames): aoc_cli.formats.impute, .bins, .outcomes
    impute: str | None = None
    impute_mask: bool = False
    impute_like: str | None = None
    outcome: str | None = None
    outcome_reward: str | dict | None = None
    bin_actions: str | dict | None = None
    bin_like: str | None = None
    censored_column: str | None = None
    #: keep a column of another role (the outcome, reward, an action, the censoring or
    #: terminal flag, the stay id, the time) listed among the observations: refused
    #: otherwise (it would leak into the state), and left out of the default ones
    allow_role_overlap: bool = False
    #: the preprocessing of the corpora named by ``impute_like``/``bin_like`` or appended
    #: to (``{"impute": ..., "bins": ..., "from": {"impute": name, "bins": name}}``), set by
    #: :func:`aoc_cli.formats.ingest`
    fitted: dict = field(default_factory=dict)


@contextlib.contextmanager
def open_h5(path: Path) -> Iterator[h5py.File]:
    """Open an HDF5 file read-only; a corrupt or truncated file is an AocError.

    Errors raised while reading inside the block (h5py raises OSError for damaged chunks and
    truncated data) become the same one-line AocError.
    """
    try:
        f = h5py.File(path, "r")
    except OSError as err:
        raise AocError(f"cannot read {path}: not a readable HDF5 file, truncated or corrupt "
                       f"({_short(err)}); re-download or re-export it") from None
    try:
        yield f
    except (OSError, RuntimeError) as err:
        raise AocError(f"cannot read {path}: the HDF5 file is truncated or corrupt "
                       f"({_short(err)}); re-download or re-export it") from None
    finally:
        with contextlib.suppress(Exception):
            f.close()


def _short(err: Exception) -> str:
    return str(err).splitlines()[0][:160] if str(err) else type(err).__name__


def check_lengths(arrays: dict[str, np.ndarray | None]) -> int:
    """All arrays (None skipped) have the same first dimension; return it."""
    lengths = {k: len(v) for k, v in arrays.items() if v is not None}
    if len(set(lengths.values())) > 1:
        raise AocError("arrays of different lengths: "
                       + ", ".join(f"{k} has {v} rows" for k, v in lengths.items())
                       + "; every array needs one entry per step")
    return next(iter(lengths.values()), 0)


def encode_labels(values: np.ndarray) -> tuple[np.ndarray, list[str]]:
    """Any per-row values (N,) -> (codes (N,) int32, sorted labels as strings)."""
    values = np.asarray(values)
    if values.ndim != 1:
        values = values.reshape(len(values), -1)
        if values.shape[1] != 1:
            raise AocError("a tag column must hold one value per row, got shape "
                           f"{values.shape}")
        values = values[:, 0]
    if values.dtype.kind == "f" and np.all(np.isfinite(values)) and \
            np.all(values == np.round(values)):
        values = values.astype(np.int64)
    if values.dtype.kind == "S":
        values = np.char.decode(values, "utf-8")
    uniq, codes = np.unique(values, return_inverse=True)
    return codes.astype(np.int32), [str(u) for u in uniq]


def action_space_of(actions: np.ndarray, discrete: bool, names=None) -> tuple[np.ndarray, dict]:
    """Actions and their space when the source declares none: integer (or ``discrete``) ->
    discrete with n = max + 1; else a box whose bounds are the observed min and max."""
    actions = np.asarray(actions)
    if discrete or (actions.dtype.kind in "iub" and actions.ndim <= 2 and
                    (actions.ndim == 1 or actions.shape[1] == 1)):
        flat = actions.reshape(len(actions))
        if len(flat) and flat.dtype.kind == "f":
            ok = np.isfinite(flat) & (flat == np.round(flat))
            if not ok.all():
                bad = int(np.flatnonzero(~ok)[0])
                raise AocError(f"discrete action of row {bad} is not an integer: {flat[bad]}; "
                               f"drop {param('discrete_actions')} for continuous actions")
        flat = flat.astype(np.int64)
        if len(flat) and flat.min() < 0:
            raise AocError(f"discrete actions must be 0, 1, 2, ...; row "
                           f"{int(np.argmin(flat))} has {int(flat.min())}")
        return flat, discrete_space(int(flat.max()) + 1 if len(flat) else 1, names)
    actions = actions.reshape(len(actions), int(np.prod(actions.shape[1:])))
    if not np.issubdtype(actions.dtype, np.floating):
        actions = actions.astype(np.float32)
    space = box_space(actions.shape[1], names=names)
    if len(actions):
        space.update(observed_bounds(actions), bounds="observed")
    return actions, space


def observed_bounds(actions: np.ndarray) -> dict:
    """``{"low": [...], "high": [...]}``: the per-dimension min and max of (N, d_a) actions,
    ignoring NaN (all-NaN dimensions give None)."""
    if all_finite(actions):
        low, high = actions.min(axis=0), actions.max(axis=0)
    else:
        finite = np.where(np.isfinite(actions), actions, np.nan)
        with np.errstate(invalid="ignore"), warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)
            low, high = np.nanmin(finite, axis=0), np.nanmax(finite, axis=0)
    return {"low": [None if not np.isfinite(x) else float(x) for x in low],
            "high": [None if not np.isfinite(x) else float(x) for x in high]}


def check_numeric(arrays: dict[str, np.ndarray | None], path) -> None:
    """Every array holds numbers (or booleans): strings, objects or compound types are an
    AocError naming the array and the file."""
    for key, arr in arrays.items():
        if arr is None:
            continue
        kind = np.asarray(arr).dtype.kind
        if kind not in "fiub":
            raise AocError(f"{path}: {key} holds {np.asarray(arr).dtype} values, not numbers: "
                           "store numeric arrays")


def flat_observations(obs: np.ndarray) -> np.ndarray:
    """(N, ...) -> (N, d_o); integers become float32. Observations of more than one
    dimension per row (images, grids) are flattened, with a warning."""
    obs = np.asarray(obs)
    if obs.ndim > 2:
        warn(f"observations of shape {tuple(obs.shape)} are flattened to "
             f"({len(obs)}, {int(np.prod(obs.shape[1:]))}), row-major")
    obs = obs.reshape(len(obs), int(np.prod(obs.shape[1:])))
    if not np.issubdtype(obs.dtype, np.floating):
        obs = obs.astype(np.float32)
    return obs


def from_flat(
    observations: np.ndarray,
    actions: np.ndarray,
    rewards: np.ndarray | None,
    terminals: np.ndarray | None,
    timeouts: np.ndarray | None,
    source: dict,
    options: ReadOptions,
    extra: dict[str, np.ndarray] | None = None,
    episode_ends: np.ndarray | None = None,
) -> CorpusData:
    """D4RL-style flat arrays -> CorpusData.

    An episode ends at a row where ``terminals | timeouts`` (or ``episode_ends``) is set; a
    trailing episode with neither is kept and marked truncated on its last row. Timeouts become
    truncations (a row that is both is a terminal). ``extra`` holds per-row arrays that
    ``--tag-column`` may name and that numeric 1-d ones become corpus ``columns``.
    """
    extra = extra or {}
    arrays = {"observations": observations, "actions": actions, "rewards": rewards,
              "terminals": terminals, "timeouts": timeouts, "episode_terminals": episode_ends}
    where = source.get("path", "the input")
    check_numeric(arrays, where)
    n = check_lengths(arrays)
    for key in ("rewards", "terminals", "timeouts", "episode_terminals"):
        if arrays[key] is not None and np.asarray(arrays[key]).size != n:
            raise AocError(f"{where}: {key} must hold one value per row, got shape "
                           f"{tuple(np.asarray(arrays[key]).shape)} for {n} rows")
    term = np.zeros(n, bool) if terminals is None else np.asarray(terminals).reshape(n) != 0
    tout = np.zeros(n, bool) if timeouts is None else np.asarray(timeouts).reshape(n) != 0
    ends = term | tout
    if episode_ends is not None:
        ends |= np.asarray(episode_ends).reshape(n) != 0
    trunc = ends & ~term
    if n and not ends[-1]:
        trunc[-1] = True
        ends[-1] = True
    stops = np.flatnonzero(ends) + 1
    starts = np.concatenate([[0], stops]).astype(np.int64)
    obs = flat_observations(observations)
    act, act_space = action_space_of(actions, options.discrete_actions)
    tags = {}
    for col in options.tag_columns:
        if col not in extra:
            known = ", ".join(sorted(extra)) or "none"
            raise AocError(f"{param('tag_columns')} {col!r} is not in the file (per-row arrays: "
                           f"{known})")
        check_lengths({"observations": observations, col: extra[col]})
        tags[col] = encode_labels(extra[col])
    columns = {k: np.asarray(v, dtype=np.float64) for k, v in extra.items()
               if k not in options.tag_columns and np.asarray(v).ndim == 1
               and np.asarray(v).dtype.kind in "fiub" and len(v) == n}
    return CorpusData(
        observations=obs, actions=act,
        rewards=None if rewards is None else np.asarray(rewards, np.float64).reshape(n),
        terminals=term, truncations=trunc,
        episode_starts=starts if n else episode_starts_from_lengths([]),
        observation_space=box_space(obs.shape[1]),
        action_space=act_space,
        tags=tags, columns=columns, source=source,
    )
