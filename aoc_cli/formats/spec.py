"""What an exported file carries so that reading it back gives the same corpus, byte for byte.

Minari, D4RL HDF5 and CSV hold rows, but not everything a corpus is: the observation and
action spaces as aoc wrote them (names, bounds, static covariates, action labels), the dtypes,
the order of each tag's labels (a tag's codes index its labels, and readers otherwise sort
them), which per-row arrays are tags and which are numeric columns, the episodes' own ids
(patient ids), and where an episode ends without a terminal or truncation flag.
:func:`describe` writes that down as one JSON object (the *export spec*): in the Minari
dataset's ``metadata.json`` (key ``aoc``), as the D4RL file's ``metadata/aoc`` string, and in
the CSV's column mapping (``NAME.columns.json``, key ``aoc``). A reader that finds it calls
:func:`restore` on what it read; without it the file reads as any other of its format.

The spec also records the content hash of what was exported: :func:`restore` warns when the
data read back differ (a file edited after export). And what a clinical corpus was prepared
with: its ``preprocessing`` (imputation rule and medians, dose-bin edges, the split) and its
imputed-cell mask (``imputed``: the (N, d_o) bits packed row-major, zlib-compressed, base64;
:func:`pack_mask`), so that a corpus read back from any of the three formats still marks its
imputed cells and fills appended or held-out data with its own medians.
"""

from __future__ import annotations

import base64
import json
import zlib

import numpy as np

from aoc_cli.errors import AocError, warn
from aoc_cli.store import CorpusData, episode_starts_from_lengths
from aoc_cli.store.atomic import content_hash

SPEC_KEY = "aoc"
SPEC_VERSION = 1


def content_hash_of(data: CorpusData) -> str:
    """The store's content hash of in-memory corpus data (as ``manifest.json`` records it)."""
    return content_hash(data.observations, data.actions, data.rewards, data.terminals,
                        data.truncations, data.episode_starts,
                        {k: c for k, (c, _labels) in data.tags.items()}, data.columns)


def unflagged_ends(data: CorpusData) -> list[int]:
    """Episodes whose last row is neither terminal nor truncated (formats that mark episode
    ends by those flags alone flag them as timeouts; the spec says which were not)."""
    last = np.asarray(data.episode_starts[1:]) - 1
    flagged = np.asarray(data.terminals)[last] | np.asarray(data.truncations)[last]
    return np.flatnonzero(~flagged).astype(int).tolist()


def describe(data: CorpusData, corpus: str, fmt: str, content_hash: str | None = None) -> dict:
    """The export spec of ``data`` (exported from corpus ``corpus`` to format ``fmt``);
    ``content_hash``: the data's, when known (a whole stored corpus: its manifest's), else
    computed."""
    return {
        "version": SPEC_VERSION,
        "corpus": corpus,
        "format": fmt,
        "rows": data.n_rows,
        "episodes": data.n_episodes,
        "content_hash": content_hash or content_hash_of(data),
        "observation_space": data.observation_space,
        "action_space": data.action_space,
        "observations_dtype": np.asarray(data.observations).dtype.str,
        "actions_dtype": np.asarray(data.actions).dtype.str,
        "has_rewards": data.rewards is not None,
        "tags": {k: list(labels) for k, (_c, labels) in data.tags.items()},
        "columns": list(data.columns),
        "episode_ids": None if data.episode_ids is None else list(data.episode_ids),
        "unflagged_ends": unflagged_ends(data),
        "source": data.source,
        "preprocessing": data.preprocessing or {},
        "imputed": None if data.imputed is None else pack_mask(data.imputed),
    }


def pack_mask(mask: np.ndarray) -> dict:
    """An (N, d) bool mask as JSON: ``{"shape", "bits"}``, the bits packed row-major,
    zlib-compressed, base64 (229k x 44 cells with 15% set: ~0.9 MB of text)."""
    mask = np.ascontiguousarray(mask, dtype=bool)
    packed = zlib.compress(np.packbits(mask.reshape(-1)).tobytes(), 6)
    return {"shape": list(mask.shape), "bits": base64.b64encode(packed).decode("ascii")}


def unpack_mask(packed: dict, shape: tuple[int, int], where) -> np.ndarray:
    """The mask :func:`pack_mask` wrote, checked to be of ``shape`` (the observations read
    back); anything else is an AocError naming the file."""
    bad = AocError(f"{where}: the imputed-cell mask of the export metadata does not fit the "
                   f"observations {tuple(shape)}; re-export the corpus")
    if not isinstance(packed, dict) or [int(x) for x in packed.get("shape", [])] != \
            list(shape):
        raise bad
    n = int(shape[0]) * int(shape[1])
    try:
        raw = zlib.decompressobj().decompress(base64.b64decode(packed["bits"]), (n + 7) // 8)
    except (ValueError, TypeError, KeyError, zlib.error):
        raise bad from None
    if len(raw) != (n + 7) // 8:
        raise bad
    return np.unpackbits(np.frombuffer(raw, np.uint8), count=n).astype(bool).reshape(shape)


def parse_spec(value, where) -> dict | None:
    """The spec stored in a file (a dict, or JSON text or bytes), None when absent; a spec
    that is not one is an AocError naming the file."""
    if value is None:
        return None
    try:
        if isinstance(value, bytes):
            value = value.decode("utf-8")
        spec = json.loads(value) if isinstance(value, str) else value
    except (UnicodeDecodeError, json.JSONDecodeError) as err:
        raise AocError(f"{where}: the export metadata is not JSON ({err}); re-export "
                       "the corpus") from None
    keys = ("rows", "episodes", "observation_space", "action_space", "observations_dtype",
            "actions_dtype", "has_rewards", "tags", "columns")
    missing = [k for k in keys if not isinstance(spec, dict) or k not in spec]
    if missing:
        raise AocError(f"{where}: the export metadata lacks {', '.join(missing)}; "
                       "re-export the corpus")
    if spec.get("version", SPEC_VERSION) > SPEC_VERSION:
        raise AocError(f"{where} was exported by a newer aoc (export spec version "
                       f"{spec['version']}): upgrade aoc to read it exactly")
    return spec


def take_episodes(data: CorpusData, order: np.ndarray) -> CorpusData:
    """A copy holding episodes ``order`` (E',) in that order."""
    starts = np.asarray(data.episode_starts)
    lengths = np.diff(starts)[order]
    rows = np.concatenate([np.arange(starts[e], starts[e + 1]) for e in order]) \
        if len(order) else np.zeros(0, np.int64)
    return CorpusData(
        observations=np.asarray(data.observations)[rows],
        actions=np.asarray(data.actions)[rows],
        rewards=None if data.rewards is None else np.asarray(data.rewards)[rows],
        terminals=np.asarray(data.terminals)[rows],
        truncations=np.asarray(data.truncations)[rows],
        episode_starts=episode_starts_from_lengths(lengths),
        observation_space=data.observation_space, action_space=data.action_space,
        tags={k: (np.asarray(c)[rows], lab) for k, (c, lab) in data.tags.items()},
        columns={k: np.asarray(v)[rows] for k, v in data.columns.items()},
        episode_ids=None if data.episode_ids is None
        else [data.episode_ids[e] for e in order],
        source=data.source,
        imputed=None if data.imputed is None else np.asarray(data.imputed)[rows],
        preprocessing=data.preprocessing,
    )


def _cast(arr: np.ndarray, dtype: str, what: str, where) -> np.ndarray:
    """``arr`` as ``dtype``: floats to the exported float type (text read as float64 rounds
    to the float32 it was written from); other casts only when every value survives them,
    else unchanged (a warning)."""
    arr = np.asarray(arr)
    target = np.dtype(dtype)
    if arr.dtype == target:
        return arr
    out = arr.astype(target)
    if arr.dtype.kind == "f" and target.kind == "f":
        return out
    same = np.array_equal(out.astype(arr.dtype), arr, equal_nan=arr.dtype.kind == "f")
    if not same:
        warn(f"{where}: {what} hold values that {target} cannot represent (edited after "
             f"export?); kept as {arr.dtype}")
        return arr
    return out


def _recode(codes: np.ndarray, have: list[str], labels: list[str], name: str,
            where) -> np.ndarray:
    """Codes indexing ``have`` -> codes indexing ``labels`` (int32)."""
    missing = [h for h in have if h not in labels]
    if missing:
        raise AocError(f"{where}: tag {name!r} holds {missing[0]!r}, which the export "
                       f"metadata does not list (labels: {', '.join(labels)}); the file was "
                       "edited after export: re-export it, or read it without its metadata")
    remap = np.array([labels.index(h) for h in have] or [0], dtype=np.int32)
    return remap[np.asarray(codes, dtype=np.int64)]


def restore(data: CorpusData, spec: dict, where) -> CorpusData:
    """``data`` as read from an exported file -> the corpus that was exported: dtypes, tag
    label order, columns, spaces, episode ids and the episode ends flagged only for the
    format are put back as ``spec`` records them. Tags of ``data`` are (codes, labels) and
    are matched by label text."""
    if data.n_rows != spec["rows"] or data.n_episodes != spec["episodes"]:
        raise AocError(f"{where} holds {data.n_rows} rows in {data.n_episodes} episodes, its "
                       f"export metadata {spec['rows']} in {spec['episodes']}: the file was "
                       "edited after export; re-export it, or read it without its metadata")
    act_space = spec["action_space"]
    actions = np.asarray(data.actions)
    if act_space.get("type") == "discrete":
        actions = actions.reshape(len(actions)).astype(np.int64)
    else:
        actions = _cast(actions, spec["actions_dtype"], "actions", where)
    tags = {}
    for name, labels in spec["tags"].items():
        if name not in data.tags:
            raise AocError(f"{where}: tag {name!r} of the export metadata is missing from the "
                           "data; re-export it")
        codes, have = data.tags[name]
        tags[name] = (_recode(codes, list(have), list(labels), name, where), list(labels))
    for name, value in data.tags.items():  # tags added while reading (--tag)
        tags.setdefault(name, value)
    missing = [c for c in spec["columns"] if c not in data.columns]
    if missing:
        raise AocError(f"{where}: column {missing[0]!r} of the export metadata is missing from "
                       "the data; re-export it")
    truncations = np.asarray(data.truncations, bool).copy()
    last = np.asarray(data.episode_starts[1:]) - 1
    ends = np.asarray(spec.get("unflagged_ends") or [], np.int64)
    truncations[last[ends]] = False
    observations = _cast(data.observations, spec["observations_dtype"], "observations", where)
    imputed = None if spec.get("imputed") is None else \
        unpack_mask(spec["imputed"], np.asarray(observations).shape, where)
    out = CorpusData(
        observations=observations,
        actions=actions,
        rewards=None if not spec["has_rewards"] or data.rewards is None
        else np.asarray(data.rewards, np.float64),
        terminals=np.asarray(data.terminals, bool), truncations=truncations,
        episode_starts=np.asarray(data.episode_starts, np.int64),
        observation_space=spec["observation_space"], action_space=act_space, tags=tags,
        columns={c: np.asarray(data.columns[c], np.float64) for c in spec["columns"]},
        episode_ids=None if spec.get("episode_ids") is None else list(spec["episode_ids"]),
        source={**data.source, "exported_from": {
            "corpus": spec.get("corpus"), "content_hash": spec.get("content_hash"),
            "source": spec.get("source")}},
        imputed=imputed, preprocessing=dict(spec.get("preprocessing") or {}),
    )
    untouched = set(tags) == set(spec["tags"]) and \
        (out.rewards is not None) == bool(spec["has_rewards"])
    if spec.get("content_hash") and untouched and content_hash_of(out) != spec["content_hash"]:
        warn(f"{where}: the data differ from the corpus {spec.get('corpus')!r} that was "
             "exported (edited after export?); read as they are now")
    return out
