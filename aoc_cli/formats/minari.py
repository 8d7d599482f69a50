"""Minari datasets (HDF5 backend), read through minari's own storage.

A dataset is a folder ``.../<name>-vN/data/`` holding ``main_data.hdf5`` and
``metadata.json``; it may also be named by its id (``namespace/name-v0``) in the local Minari
datasets path (``$MINARI_DATASETS_PATH``, default ``~/.minari/datasets``).

Each Minari episode holds T + 1 observations for T actions. The corpus keeps the first T: the
observation at which each action was taken. The final observation (after the last action) is
not stored; it is recorded nowhere else in the corpus.

Observations: Box spaces are flattened; Dict spaces are flattened key by key in sorted key
order (nested dicts depth first, Tuple spaces in index order), the order stated in the
observation space's ``keys`` and ``names``; Discrete observations are one column holding the
integer. Actions: Box (flattened) or Discrete (stored as ``a - start``).

A dataset written by ``aoc export --to minari`` (:mod:`aoc_cli.formats.export_minari`) holds
the export spec in ``metadata.json`` (key ``aoc``) and its tags and columns as infos: it is
read back as the corpus that was exported (:func:`aoc_cli.formats.spec.restore`).
"""

from __future__ import annotations

import dataclasses
import json
import os
from pathlib import Path

import numpy as np

from aoc_cli.errors import AocError, param
from aoc_cli.formats.common import ReadOptions, encode_labels
from aoc_cli.formats.spec import parse_spec, restore
from aoc_cli.progress import tracked
from aoc_cli.store import CorpusData, box_space, discrete_space, episode_starts_from_lengths

BATCH_EPISODES = 256


def datasets_root() -> Path:
    """The local Minari datasets path (without creating it, unlike minari's own helper)."""
    root = os.environ.get("MINARI_DATASETS_PATH")
    return Path(root) if root else Path.home() / ".minari" / "datasets"


def data_folder(path: str | os.PathLike) -> Path | None:
    """The ``data/`` folder of a Minari dataset given as a folder, its ``main_data.hdf5`` file,
    or a dataset id in the local datasets path; None when ``path`` is none of these."""
    p = Path(path)
    candidates = [p, p / "data", p.parent if p.name == "main_data.hdf5" else None]
    if not p.exists() and not p.is_absolute():
        candidates.append(datasets_root() / str(path) / "data")
    for c in candidates:
        if c is not None and (c / "main_data.hdf5").is_file() and (c / "metadata.json").is_file():
            return c
    return None


def read_minari(path: str | os.PathLike, options: ReadOptions) -> CorpusData:
    """Read a Minari dataset folder or id."""
    folder = data_folder(path)
    if folder is None:
        raise AocError(f"{path} is not a Minari dataset: expected a folder with main_data.hdf5 "
                       f"and metadata.json, or a dataset id under {datasets_root()} "
                       "(set MINARI_DATASETS_PATH)")
    meta, dataset = _open(folder)
    spec = parse_spec(meta.get("aoc"), folder)
    own = options
    if spec is not None:  # the exported tags and columns are infos
        named = list(spec["tags"]) + list(spec["columns"])
        options = dataclasses.replace(options, tag_columns=named + [
            c for c in options.tag_columns if c not in named])
    flatten, obs_names, keys = _flattener(dataset.observation_space)
    to_action, action_space = _action_reader(dataset.action_space)
    eps = _read_episodes(dataset, folder, options, flatten, to_action)
    keep = [i for i, t in enumerate(eps["lengths"]) if t > 0]
    if not keep:
        raise AocError(f"Minari dataset {folder} holds zero steps: nothing to store")

    def joined(key):
        return np.concatenate([eps[key][i] for i in keep])

    observations = joined("obs")
    obs_space_json = box_space(observations.shape[1], names=obs_names)
    low, high = _bounds(dataset.observation_space)
    if low is not None:
        obs_space_json.update(low=low, high=high)
    if keys:
        obs_space_json["keys"] = keys
    data = CorpusData(
        observations=observations, actions=joined("act"), rewards=joined("rew"),
        terminals=joined("term"), truncations=joined("trunc"),
        episode_starts=episode_starts_from_lengths(np.asarray(eps["lengths"], np.int64)[keep]),
        observation_space=obs_space_json,
        action_space=action_space,
        tags={c: encode_labels(np.concatenate([v[i] for i in keep]))
              for c, v in eps["tags"].items()} if spec is None else {},
        episode_ids=[eps["ids"][i] for i in keep],
        source={"format": "minari", "path": str(folder.resolve()),
                "dataset_id": meta.get("dataset_id"),
                "algorithm_name": meta.get("algorithm_name"),
                "minari_version": meta.get("minari_version")},
    )
    if spec is None:
        return data
    infos = {c: np.concatenate([v[i] for i in keep]) for c, v in eps["tags"].items()}
    data.tags = {k: (infos[k], spec["tags"][k]) for k in spec["tags"]}
    data.tags.update({k: encode_labels(infos[k]) for k in own.tag_columns
                      if k not in spec["tags"]})
    data.columns = {k: infos[k] for k in spec["columns"]}
    return restore(data, spec, folder)


def _open(folder: Path):
    """(metadata dict, minari.MinariDataset); damaged files are one AocError."""
    import minari

    try:
        meta = json.loads((folder / "metadata.json").read_text())
        dataset = minari.MinariDataset(folder)
        dataset.observation_space, dataset.action_space, int(dataset.total_episodes)
    except (OSError, ValueError, KeyError, TypeError, AttributeError, AssertionError,
            json.JSONDecodeError) as err:
        text = str(err).splitlines()[0] if str(err).strip() else \
            f"{type(err).__name__}: metadata.json lacks what minari needs"
        raise AocError(f"cannot read Minari dataset {folder}: {text}; the files are "
                       "truncated or corrupt, re-download the dataset") from None
    if not isinstance(meta, dict):
        raise AocError(f"cannot read Minari dataset {folder}: metadata.json is not a JSON "
                       "object; re-download the dataset")
    return meta, dataset


def _read_episodes(dataset, folder: Path, options: ReadOptions, flatten, to_action) -> dict:
    """Every episode's arrays, in batches: lists under obs, act, rew, term, trunc, lengths,
    ids, and tags {column: list}."""
    out = {k: [] for k in ("obs", "act", "rew", "term", "trunc", "lengths", "ids")}
    out["tags"] = {c: [] for c in options.tag_columns}
    indices = list(dataset.episode_indices)
    batches = [indices[i:i + BATCH_EPISODES] for i in range(0, len(indices), BATCH_EPISODES)]
    progress = options.progress if len(batches) > 1 else None
    try:
        for batch in tracked(batches, progress, "reading Minari episodes", len(batches)):
            for ep in dataset.storage.get_episodes(batch):
                _add_episode(out, ep, options, flatten, to_action)
    except (OSError, RuntimeError, ValueError, TypeError, KeyError) as err:
        raise AocError(f"cannot read Minari dataset {folder}: {str(err).splitlines()[0]}; the "
                       "HDF5 file is truncated or corrupt, re-download the dataset") from None
    return out


def _add_episode(out: dict, ep: dict, options: ReadOptions, flatten, to_action) -> None:
    t = len(ep["rewards"])
    o = flatten(ep["observations"])
    if len(o) not in (t, t + 1):
        raise AocError(f"Minari episode {ep['id']} has {len(o)} observations for "
                       f"{t} actions: the dataset is inconsistent")
    out["obs"].append(o[:t])
    out["act"].append(to_action(ep["actions"]))
    out["rew"].append(np.asarray(ep["rewards"], np.float64).reshape(-1))
    out["term"].append(np.asarray(ep["terminations"], bool).reshape(-1))
    out["trunc"].append(np.asarray(ep["truncations"], bool).reshape(-1))
    out["lengths"].append(t)
    out["ids"].append(str(ep["id"]))
    for col in options.tag_columns:
        infos = ep.get("infos") or {}
        if col not in infos:
            raise AocError(f"{param('tag_columns')} {col!r} is not an info key of the Minari "
                           f"dataset (info keys: {', '.join(sorted(infos)) or 'none'})")
        out["tags"][col].append(np.asarray(infos[col])[:t])


def _flattener(space):
    """(flatten(obs) -> (T, d_o) float, names or None, dict keys or None) for a space."""
    from gymnasium import spaces

    def leaves(sp, prefix):
        """[(path, leaf space)] in flattening order."""
        if isinstance(sp, spaces.Dict):
            return [x for k in sorted(sp.spaces) for x in leaves(sp.spaces[k], prefix + (k,))]
        if isinstance(sp, spaces.Tuple):
            return [x for i, s in enumerate(sp.spaces) for x in leaves(s, prefix + (i,))]
        if isinstance(sp, (spaces.Box, spaces.Discrete, spaces.MultiBinary,
                           spaces.MultiDiscrete)):
            return [(prefix, sp)]
        raise AocError(f"unsupported Minari observation space {sp}: use Box, Discrete, Dict "
                       "or Tuple observations")

    paths = leaves(space, ())

    def pick(obs, path):
        for k in path:
            obs = obs[k] if isinstance(obs, dict) else obs[k]
        return obs

    def flatten(obs):
        parts = [np.asarray(pick(obs, p)) for p, _ in paths]
        parts = [p.reshape(len(p), int(np.prod(p.shape[1:]))).astype(
            p.dtype if np.issubdtype(p.dtype, np.floating) else np.float32) for p in parts]
        return parts[0] if len(parts) == 1 else np.concatenate(
            [p.astype(np.result_type(*parts)) for p in parts], axis=1)

    if paths == [((), space)]:
        return flatten, None, None
    names = []
    for path, sp in paths:
        label = "/".join(str(k) for k in path)
        size = 1 if isinstance(sp, spaces.Discrete) else int(np.prod(sp.shape))
        names += [label] if size == 1 else [f"{label}[{i}]" for i in range(size)]
    keys = ["/".join(str(k) for k in path) for path, _ in paths]
    return flatten, names, keys


def _bounds(space):
    """Flattened finite low/high of a Box observation space, else (None, None)."""
    from gymnasium import spaces

    if isinstance(space, spaces.Box):
        low, high = space.low.reshape(-1), space.high.reshape(-1)
        if np.all(np.isfinite(low)) and np.all(np.isfinite(high)):
            return low.astype(float).tolist(), high.astype(float).tolist()
    return None, None


def _action_reader(space):
    """(actions -> (T, d_a) float or (T,) int, the action space as JSON)."""
    from gymnasium import spaces

    if isinstance(space, spaces.Discrete):
        start = int(space.start)
        out = discrete_space(int(space.n))
        if start:
            out["start"] = start
        return (lambda a: np.asarray(a).reshape(-1).astype(np.int64) - start), out
    if isinstance(space, spaces.Box):
        d = int(np.prod(space.shape))
        low, high = space.low.reshape(-1), space.high.reshape(-1)
        out = box_space(d, low if np.all(np.isfinite(low)) else None,
                        high if np.all(np.isfinite(high)) else None)

        def to_action(a):
            a = np.asarray(a)
            a = a.reshape(len(a), d)
            return a if np.issubdtype(a.dtype, np.floating) else a.astype(np.float32)

        return to_action, out
    raise AocError(f"unsupported Minari action space {space}: aoc reads Box and Discrete "
                   "actions")
