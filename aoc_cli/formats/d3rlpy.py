"""d3rlpy ReplayBuffer dumps (``buffer.dump(f)``, format version 2.x), read with h5py alone.

Root datasets ``columns``, ``num_episodes``, ``version``; per episode i: ``observations_{i}``
(T, ...) (tuple observations: ``observations_{i}_{j}``, flattened and joined in j order),
``actions_{i}`` (T, ...), ``rewards_{i}`` (T, 1), ``terminated_{i}`` (scalar). An episode
holds T observations, one per action. ``terminated`` marks the last row a terminal; otherwise
the episode was cut off and its last row is marked truncated. Integer actions are discrete.

Also read: the flat d3rlpy 1.x ``MDPDataset.dump`` layout (``observations``, ``actions``,
``rewards``, ``terminals``, ``episode_terminals``), where an episode ends at
``episode_terminals`` and a row that is not ``terminals`` is a truncation.
"""

from __future__ import annotations

import re
from pathlib import Path

import h5py
import numpy as np

from aoc_cli.errors import AocError, param
from aoc_cli.formats.common import (
    ReadOptions,
    action_space_of,
    check_lengths,
    flat_observations,
    from_flat,
    open_h5,
)
from aoc_cli.progress import tracked
from aoc_cli.store import CorpusData, box_space, episode_starts_from_lengths

_EPISODE_KEY = re.compile(r"^observations_(\d+)(?:_\d+)?$")


def is_d3rlpy(f: h5py.File) -> bool:
    """True for a d3rlpy 2.x dump or a d3rlpy 1.x flat MDPDataset dump."""
    keys = set(f.keys())
    if "num_episodes" in keys or "observations_0" in keys or "observations_0_0" in keys:
        return True
    return {"observations", "actions", "episode_terminals"} <= keys


def read_d3rlpy(path: Path, options: ReadOptions) -> CorpusData:
    """Read a d3rlpy dump."""
    source = {"format": "d3rlpy", "path": str(Path(path).resolve())}
    with open_h5(path) as f:
        if not is_d3rlpy(f):
            raise AocError(f"{path} is not a d3rlpy dump: no num_episodes, observations_0 or "
                           f"episode_terminals (keys: {', '.join(sorted(f.keys())[:8])})")
        if "episode_terminals" in f:
            get = {k: f[k][()] if k in f else None
                   for k in ("observations", "actions", "rewards", "terminals",
                             "episode_terminals")}
            source["version"] = "1.x"
            return from_flat(get["observations"], get["actions"], get["rewards"],
                             get["terminals"], None, source, options,
                             episode_ends=get["episode_terminals"])
        if options.tag_columns:
            raise AocError(f"d3rlpy dumps have no per-row columns for {param('tag_columns')}: "
                           f"use {param('tags')} "
                           "KEY=VALUE for a constant tag")
        if "num_episodes" in f:
            n_ep = int(f["num_episodes"][()])
        else:
            n_ep = 1 + max(int(m.group(1)) for k in f.keys() if (m := _EPISODE_KEY.match(k)))
        version = f["version"][()] if "version" in f else b"?"
        source["version"] = version.decode() if isinstance(version, bytes) else str(version)
        obs, act, rew, term, lengths = [], [], [], [], []
        progress = options.progress if n_ep > 100 else None
        for i in tracked(range(n_ep), progress, "reading d3rlpy episodes", n_ep):
            o = _observations(f, i, path)
            a = _get(f, f"actions_{i}", path)
            r = _get(f, f"rewards_{i}", path).reshape(-1) if f"rewards_{i}" in f else None
            t = len(o)
            check_lengths({f"observations_{i}": o, f"actions_{i}": a, f"rewards_{i}": r})
            obs.append(o)
            act.append(a)
            rew.append(r)
            term.append(bool(np.asarray(_get(f, f"terminated_{i}", path)).reshape(-1)[0])
                        if f"terminated_{i}" in f else False)
            lengths.append(t)
    if not lengths or sum(lengths) == 0:
        raise AocError(f"{path} holds zero rows: nothing to store")
    lengths = np.asarray(lengths, dtype=np.int64)
    terminated = np.asarray(term, bool)[lengths > 0]  # empty episodes carry no rows
    lengths = lengths[lengths > 0]
    starts = episode_starts_from_lengths(lengths)
    observations = np.concatenate(obs)
    actions, act_space = action_space_of(np.concatenate(act), options.discrete_actions)
    n = len(observations)
    last = starts[1:] - 1
    terminals = np.zeros(n, bool)
    truncations = np.zeros(n, bool)
    terminals[last[terminated]] = True
    truncations[last[~terminated]] = True
    has_rewards = all(r is not None for r in rew)
    return CorpusData(
        observations=observations, actions=actions,
        rewards=np.concatenate(rew).astype(np.float64) if has_rewards else None,
        terminals=terminals, truncations=truncations, episode_starts=starts,
        observation_space=box_space(observations.shape[1]), action_space=act_space,
        source=source,
    )


def _get(f: h5py.File, key: str, path: Path) -> np.ndarray:
    if key not in f:
        raise AocError(f"{path}: d3rlpy dump is missing {key!r}; the file is incomplete")
    return f[key][()]


def _observations(f: h5py.File, i: int, path: Path) -> np.ndarray:
    """(T, d_o) observations of episode i (tuple observations joined in order)."""
    if f"observations_{i}" in f:
        return flat_observations(f[f"observations_{i}"][()])
    parts = []
    j = 0
    while f"observations_{i}_{j}" in f:
        parts.append(flat_observations(f[f"observations_{i}_{j}"][()]))
        j += 1
    if not parts:
        raise AocError(f"{path}: d3rlpy dump is missing observations_{i}; the file is "
                       "incomplete")
    return np.concatenate(parts, axis=1)
