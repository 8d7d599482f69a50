"""CSV logs of tabular data (the healthcare case): one row per time step.

Column roles come from flags, else a small JSON mapping file (``--columns FILE``), else the
defaults:

==============  ==============================  =====================================
role            mapping key                     default
==============  ==============================  =====================================
episode id      ``id``                          ``episode``, else ``id``, else one episode
time            ``time``                        ``t``, else ``time``, else file order
observations    ``observations`` (names/globs)  ``obs_*``
actions         ``actions`` (names/globs)       ``act_*``
reward          ``reward``                      ``reward`` if present
terminal flag   ``terminal``                    the last row of every episode
tag columns     ``tags`` (list)                 none
discrete        ``discrete_actions`` (bool)     false
static id       ``static_id``                   the episode id column's name
==============  ==============================  =====================================

Rows are ordered by episode id and time whatever the file's order (ids numerically when they
are all numbers; times as numbers or ISO dates). The episode ids are kept. A second CSV of
static per-episode features (``--static FILE``, one row per id) is joined onto every step and
appended to the observation: numeric columns as they are, text columns one-hot (``sex=F``,
``sex=M``); the names are recorded in the observation space's ``names`` and ``static``.
Remaining numeric columns are kept as corpus columns (usable as value targets).
"""

from __future__ import annotations

import csv
import fnmatch
import gzip
import json
from pathlib import Path

import numpy as np

from aoc_cli.errors import AocError
from aoc_cli.formats.common import ReadOptions, action_space_of, encode_labels, no_progress
from aoc_cli.store import CorpusData, box_space

CHUNK_LINES = 50_000
MAPPING_KEYS = {"id", "time", "observations", "actions", "reward", "terminal", "tags",
                "discrete_actions", "static_id"}


def read_table(path: Path, progress=None) -> tuple[list[str], dict[str, np.ndarray]]:
    """A CSV (``.tsv``: tab-separated; ``.gz``: gzip) -> (header, column name -> (N,) str)."""
    opener = gzip.open if path.suffix == ".gz" else open
    try:
        with opener(path, "rt", encoding="utf-8-sig", newline="") as fh:
            text = fh.read()
    except (OSError, UnicodeDecodeError, EOFError) as err:
        raise AocError(f"cannot read {path} as UTF-8 text ({err})") from None
    delimiter = "\t" if ".tsv" in path.suffixes else ","
    lines = text.splitlines()
    if not lines:
        raise AocError(f"{path} is empty: expected a header line and one row per step")
    header = [h.strip() for h in next(csv.reader([lines[0]], delimiter=delimiter))]
    if len(set(header)) != len(header):
        dup = sorted({h for h in header if header.count(h) > 1})
        raise AocError(f"{path} repeats column names {dup}: rename them")
    body = [ln for ln in lines[1:] if ln.strip()]
    rows: list[list[str]] = []
    chunks = range(0, len(body), CHUNK_LINES)
    if progress is None or len(chunks) < 2:  # no bar for a file read in one go
        progress = no_progress
    for start in progress(chunks, f"reading {path.name}", len(chunks)):
        part = list(csv.reader(body[start:start + CHUNK_LINES], delimiter=delimiter))
        for i, r in enumerate(part):
            if len(r) != len(header):
                raise AocError(f"{path}: data row {start + i + 1} has {len(r)} fields, the "
                               f"header has {len(header)}: fix the file")
        rows.extend(part)
    if not rows:
        return header, {h: np.array([], dtype=str) for h in header}
    cols = [np.array(c, dtype=str) for c in zip(*rows)]
    return header, dict(zip(header, cols))


def numeric(values: np.ndarray, name: str, path: Path) -> np.ndarray:
    """(N,) strings -> float64; empty cells are NaN; anything else that is not a number is
    an AocError naming the row."""
    stripped = np.char.strip(values)
    stripped = np.where(stripped == "", "nan", stripped)
    try:
        return stripped.astype(np.float64)
    except ValueError:
        for i, v in enumerate(stripped):
            try:
                float(v)
            except ValueError:
                raise AocError(f"{path}: column {name!r}, data row {i + 1} holds "
                               f"{str(v)!r}, not a number") from None
    raise AssertionError("unreachable")


def _is_numeric(values: np.ndarray) -> bool:
    try:
        np.where(np.char.strip(values) == "", "nan", np.char.strip(values)).astype(np.float64)
        return True
    except ValueError:
        return False


def _sort_key(values: np.ndarray, name: str, path: Path, dates: bool) -> np.ndarray:
    """Numbers if every value is a number, else (time only) ISO dates, else (ids) the text."""
    if _is_numeric(values):
        return numeric(values, name, path)
    if dates:
        try:
            return np.array(np.char.strip(values), dtype="datetime64[ns]").astype(np.int64)
        except ValueError:
            raise AocError(f"{path}: time column {name!r} holds neither numbers nor ISO dates "
                           f"(e.g. {str(values[0])!r})") from None
    return np.char.strip(values)


def _mapping(options: ReadOptions) -> dict:
    if options.columns_file is None:
        return {}
    try:
        mapping = json.loads(Path(options.columns_file).read_text())
    except (OSError, json.JSONDecodeError) as err:
        raise AocError(f"cannot read --columns {options.columns_file}: {err}") from None
    if not isinstance(mapping, dict) or set(mapping) - MAPPING_KEYS:
        raise AocError(f"--columns {options.columns_file} must be a JSON object with keys among "
                       f"{sorted(MAPPING_KEYS)}")
    return mapping


def _match(header: list[str], patterns, role: str, path: Path) -> list[str]:
    """Columns named by ``patterns`` (names or globs), in file order for globs."""
    patterns = [patterns] if isinstance(patterns, str) else list(patterns)
    out: list[str] = []
    for p in patterns:
        hits = [h for h in header if fnmatch.fnmatchcase(h, p)] if any(
            c in p for c in "*?[") else ([p] if p in header else [])
        if not hits:
            raise AocError(f"{path}: no column matches {role} {p!r} (columns: "
                           f"{', '.join(header)})")
        out += [h for h in hits if h not in out]
    return out


def _first_present(header, names):
    return next((n for n in names if n in header), None)


def read_csv(path: Path, options: ReadOptions) -> CorpusData:
    """Read a CSV log (and ``options.static``) into a corpus."""
    path = Path(path)
    m = _mapping(options)
    header, cols = read_table(path, options.progress)
    id_col = options.id_column or m.get("id") or _first_present(header, ("episode", "id"))
    time_col = options.time_column or m.get("time") or _first_present(header, ("t", "time"))
    for role, col in (("episode id", id_col), ("time", time_col)):
        if col is not None and col not in header:
            raise AocError(f"{path}: no {role} column {col!r} (columns: {', '.join(header)})")
    obs_cols = _match(header, options.obs_columns or m.get("observations") or "obs_*",
                      "observation column", path) if (
        options.obs_columns or m.get("observations") or
        any(fnmatch.fnmatchcase(h, "obs_*") for h in header)) else []
    act_spec = options.act_columns or m.get("actions") or "act_*"
    act_cols = _match(header, act_spec, "action column", path)
    reward_col = None
    if not options.reward_free:
        reward_col = options.reward_column or m.get("reward") or (
            "reward" if "reward" in header else None)
        if reward_col is not None and reward_col not in header:
            raise AocError(f"{path}: no reward column {reward_col!r}: name it with "
                           "--reward-column or pass --reward-free")
    term_col = options.terminal_column or m.get("terminal")
    if term_col is not None and term_col not in header:
        raise AocError(f"{path}: no terminal column {term_col!r}")
    tag_cols = list(options.tag_columns) or list(m.get("tags", []))
    discrete = options.discrete_actions or bool(m.get("discrete_actions", False))
    n = len(next(iter(cols.values()))) if cols else 0
    if n == 0:
        raise AocError(f"{path} has zero rows: nothing to store")

    # Order rows by (id, time); the sort is stable, so ties keep the file's order.
    ids_text = np.char.strip(cols[id_col]) if id_col else np.full(n, "0")
    id_key = _sort_key(cols[id_col], id_col, path, dates=False) if id_col else np.zeros(n)
    uniq_keys, id_codes = np.unique(id_key, return_inverse=True)
    time_key = _sort_key(cols[time_col], time_col, path, dates=True) if time_col \
        else np.arange(n)
    order = np.lexsort((time_key, id_codes))
    id_codes = id_codes[order]
    bounds = np.flatnonzero(np.diff(id_codes)) + 1
    starts = np.concatenate([[0], bounds, [n]]).astype(np.int64)
    first_row = order[starts[:-1]]
    episode_ids = [str(ids_text[r]) for r in first_row]

    static_names: list[str] = []
    static_feats = None
    static_tags: dict[str, np.ndarray] = {}
    if options.static is not None:
        static_id = m.get("static_id") or id_col
        if id_col is None:
            raise AocError("--static needs an episode id column to join on: name it with "
                           "--id-column")
        static_names, static_feats, static_tags = _read_static(
            Path(options.static), static_id, uniq_keys[id_codes[starts[:-1]]], episode_ids,
            bool(np.issubdtype(np.asarray(uniq_keys).dtype, np.number)), tag_cols)
    obs_names = list(obs_cols) + static_names
    if not obs_names:
        raise AocError(f"{path}: no observation columns: name them with --obs-columns, a "
                       "--columns mapping file or obs_* column names")
    lengths = np.diff(starts)
    parts = [numeric(cols[c], c, path)[order][:, None] for c in obs_cols]
    if static_feats is not None:
        parts.append(np.repeat(static_feats, lengths, axis=0))
    observations = np.concatenate(parts, axis=1)
    act_raw = np.stack([numeric(cols[c], c, path)[order] for c in act_cols], axis=1)
    if discrete and len(act_cols) != 1:
        raise AocError(f"--discrete-actions needs exactly one action column, got {act_cols}")
    actions, act_space = action_space_of(act_raw, discrete, names=act_cols)
    terminals = np.zeros(n, bool)
    truncations = np.zeros(n, bool)
    if term_col is None:
        terminals[starts[1:] - 1] = True
    else:
        terminals = numeric(cols[term_col], term_col, path)[order] != 0
        truncations[starts[1:] - 1] = ~terminals[starts[1:] - 1]
    tags = {}
    for c in tag_cols:
        if c in cols:
            tags[c] = encode_labels(np.char.strip(cols[c])[order])
        elif c in static_tags:
            tags[c] = encode_labels(np.repeat(static_tags[c], lengths))
        else:
            raise AocError(f"--tag-column {c!r} is not a column of {path}"
                           + (" or of the --static file" if options.static else ""))
    used = set(obs_cols) | set(act_cols) | set(tag_cols) | {id_col, time_col, reward_col,
                                                            term_col}
    columns = {c: numeric(cols[c], c, path)[order] for c in header
               if c not in used and _is_numeric(cols[c])}
    obs_space = box_space(observations.shape[1], names=obs_names)
    if static_names:
        obs_space["static"] = static_names
    return CorpusData(
        observations=observations, actions=actions,
        rewards=numeric(cols[reward_col], reward_col, path)[order] if reward_col else None,
        terminals=terminals, truncations=truncations, episode_starts=starts,
        observation_space=obs_space, action_space=act_space,
        tags=tags, columns=columns, episode_ids=episode_ids,
        source={"format": "csv", "path": str(path.resolve()),
                "static": str(Path(options.static).resolve()) if options.static else None,
                "roles": {"id": id_col, "time": time_col, "observations": obs_cols,
                          "actions": act_cols, "reward": reward_col, "terminal": term_col}},
    )


def _read_static(path: Path, id_col: str, episode_keys: np.ndarray, episode_ids: list[str],
                 numeric_ids: bool, tag_cols: list[str]):
    """Static per-episode features, one row per id -> (names, (E, d_s) float, tag values)."""
    header, cols = read_table(path)
    if id_col not in header:
        raise AocError(f"--static {path} has no id column {id_col!r} (columns: "
                       f"{', '.join(header)}): name it as in the main file")
    keys = numeric(cols[id_col], id_col, path) if numeric_ids else np.char.strip(cols[id_col])
    uniq, counts = np.unique(keys, return_counts=True)
    if np.any(counts > 1):
        raise AocError(f"--static {path} has several rows for id {str(uniq[counts > 1][0])!r}: "
                       "give one row per episode")
    order = np.argsort(keys, kind="stable")
    pos = np.searchsorted(keys[order], episode_keys)
    pos = np.minimum(pos, len(keys) - 1)
    found = keys[order][pos] == episode_keys
    if not found.all():
        missing = episode_ids[int(np.flatnonzero(~found)[0])]
        raise AocError(f"--static {path} has no row for episode id {missing!r}: add one")
    rows = order[pos]
    names: list[str] = []
    feats: list[np.ndarray] = []
    tags: dict[str, np.ndarray] = {}
    for c in header:
        if c == id_col:
            continue
        values = cols[c][rows]
        if c in tag_cols:
            tags[c] = np.char.strip(values)
        elif _is_numeric(values):
            names.append(c)
            feats.append(numeric(values, c, path))
        else:  # levels from the whole file, so they do not depend on which ids are present
            for level in sorted(set(np.char.strip(cols[c]).tolist())):
                names.append(f"{c}={level}")
                feats.append((np.char.strip(values) == level).astype(np.float64))
    feats_arr = np.stack(feats, axis=1) if feats else np.zeros((len(rows), 0))
    return names, feats_arr, tags


__all__ = ["read_csv", "read_table", "numeric"]
