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
``sex=M``); the names are recorded in the observation space's ``names`` and ``static``
(:mod:`aoc_cli.formats.static`). Action columns holding text (``oxygen``, ``none``) are
discrete actions whose labels are kept (:mod:`aoc_cli.formats.text_actions`). Remaining numeric
columns are kept as corpus columns (usable as value targets).

A CSV of ``aoc export`` is read back exactly with the mapping beside it
(:mod:`aoc_cli.formats.csv_exported`).
"""

from __future__ import annotations

import fnmatch
import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from aoc_cli.errors import AocError, param, warn
from aoc_cli.formats.common import ReadOptions, action_space_of, encode_labels
from aoc_cli.formats.text_actions import text_actions
from aoc_cli.formats.csv_exported import exported_mapping, restore_exported
from aoc_cli.formats.spec import parse_spec
from aoc_cli.formats.static import read_static
from aoc_cli.formats.table import is_numeric, numeric, read_table
from aoc_cli.store import CorpusData, box_space

MAPPING_KEYS = {"id", "time", "observations", "actions", "reward", "terminal", "tags",
                "discrete_actions", "static_id", "static", "aoc"}


def _sort_key(values: np.ndarray, name: str, path: Path, dates: bool) -> np.ndarray:
    """Numbers if every value is a number, else (time only) ISO dates, else (ids) the text."""
    if is_numeric(values):
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
        raise AocError(f"cannot read {param('columns_file')} {options.columns_file}: "
                       f"{err}") from None
    if not isinstance(mapping, dict) or set(mapping) - MAPPING_KEYS:
        raise AocError(f"{param('columns_file')} {options.columns_file} must be a JSON object "
                       f"with keys among {sorted(MAPPING_KEYS)}")
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


@dataclass
class Roles:
    """Which columns play which role (None: absent)."""

    id: str | None
    time: str | None
    observations: list[str]
    actions: list[str]
    reward: str | None
    terminal: str | None
    tags: list[str]
    discrete: bool
    static_id: str | None


def _roles(path: Path, header: list[str], options: ReadOptions) -> Roles:
    """Column roles from the flags, else the mapping file, else the defaults."""
    m = _mapping(options)
    id_col = options.id_column or m.get("id") or _first_present(header, ("episode", "id"))
    time_col = options.time_column or m.get("time") or _first_present(header, ("t", "time"))
    for role, col in (("episode id", id_col), ("time", time_col)):
        if col is not None and col not in header:
            raise AocError(f"{path}: no {role} column {col!r} (columns: {', '.join(header)})")
    obs_cols = _match(header, options.obs_columns or m.get("observations") or "obs_*",
                      "observation column", path) if (
        options.obs_columns or m.get("observations") or
        any(fnmatch.fnmatchcase(h, "obs_*") for h in header)) else []
    act_cols = _match(header, options.act_columns or m.get("actions") or "act_*",
                      "action column", path)
    reward_col = None
    if not options.reward_free:
        reward_col = options.reward_column or (m["reward"] if "reward" in m else (
            "reward" if "reward" in header else None))  # a mapping's null: no reward
        if reward_col is not None and reward_col not in header:
            raise AocError(f"{path}: no reward column {reward_col!r}: name it with "
                           f"{param('reward_column')} or pass {param('reward_free')}")
    term_col = options.terminal_column or m.get("terminal")
    if term_col is not None and term_col not in header:
        raise AocError(f"{path}: no terminal column {term_col!r}")
    discrete = options.discrete_actions or bool(m.get("discrete_actions", False))
    if discrete and len(act_cols) != 1:
        raise AocError(f"{param('discrete_actions')} needs exactly one action column, got "
                       f"{act_cols}")
    return Roles(id_col, time_col, obs_cols, act_cols, reward_col, term_col,
                 list(options.tag_columns) or list(m.get("tags", [])), discrete,
                 m.get("static_id") or id_col)


@dataclass
class Episodes:
    """Rows ordered by (id, time): ``order`` (N,) file row of each corpus row, ``starts``
    (E + 1,), the id of each episode as text and as its sort key."""

    order: np.ndarray
    starts: np.ndarray
    ids: list[str]
    keys: np.ndarray


def _episodes(path: Path, cols: dict, roles: Roles, n: int) -> Episodes:
    """Order the rows by episode id and time (stable: ties keep the file's order); warn
    about empty ids and repeated (id, time) pairs, which are kept."""
    ids_text = np.char.strip(cols[roles.id]) if roles.id else np.full(n, "0")
    if roles.id and (ids_text == "").any():
        rows = np.flatnonzero(ids_text == "")
        warn(f"{path}: {len(rows)} rows have an empty {roles.id!r} cell (first: data row "
             f"{int(rows[0]) + 1}); they form one episode with the id ''")
    id_key = _sort_key(cols[roles.id], roles.id, path, dates=False) if roles.id \
        else np.zeros(n)
    uniq_keys, id_codes = np.unique(id_key, return_inverse=True)
    time_key = _sort_key(cols[roles.time], roles.time, path, dates=True) if roles.time \
        else np.arange(n)
    order = np.lexsort((time_key, id_codes))
    id_codes = id_codes[order]
    if roles.time:
        same = (np.diff(id_codes) == 0) & (np.diff(np.asarray(time_key)[order]) == 0)
        if same.any():
            first = int(order[np.flatnonzero(same)[0] + 1])
            key = f"({roles.id}, {roles.time})" if roles.id else repr(roles.time)
            warn(f"{path}: {int(same.sum())} rows repeat the {key} of an earlier row (first: "
                 f"data row {first + 1}); kept in file order as successive steps")
    bounds = np.flatnonzero(np.diff(id_codes)) + 1
    starts = np.concatenate([[0], bounds, [n]]).astype(np.int64)
    return Episodes(order, starts, [str(ids_text[r]) for r in order[starts[:-1]]],
                    uniq_keys[id_codes[starts[:-1]]])


def _flags(path: Path, cols: dict, roles: Roles, eps: Episodes, n: int):
    """(terminals, truncations) (N,): each episode's last row ends it, a terminal unless the
    terminal column says otherwise (then a truncation)."""
    terminals = np.zeros(n, bool)
    truncations = np.zeros(n, bool)
    last = eps.starts[1:] - 1
    if roles.terminal is None:
        terminals[last] = True
    else:
        terminals = numeric(cols[roles.terminal], roles.terminal, path)[eps.order] != 0
        truncations[last] = ~terminals[last]
    return terminals, truncations


def _tags(path: Path, cols: dict, roles: Roles, eps: Episodes, static_tags: dict,
          has_static: bool) -> dict:
    lengths = np.diff(eps.starts)
    tags = {}
    for c in roles.tags:
        if c in cols:
            tags[c] = encode_labels(np.char.strip(cols[c])[eps.order])
        elif c in static_tags:
            tags[c] = encode_labels(np.repeat(static_tags[c], lengths))
        else:
            raise AocError(f"{param('tag_columns')} {c!r} is not a column of {path}"
                           + (f" or of the {param('static')} file" if has_static else ""))
    return tags


def read_csv(path: Path, options: ReadOptions) -> CorpusData:
    """Read a CSV log (and ``options.static``) into a corpus."""
    path = Path(path)
    options = exported_mapping(path, options)
    header, cols = read_table(path, options.progress)
    roles = _roles(path, header, options)
    n = len(next(iter(cols.values()))) if cols else 0
    if n == 0:
        raise AocError(f"{path} has zero rows: nothing to store")
    eps = _episodes(path, cols, roles, n)
    static_names: list[str] = []
    static_feats = None
    static_tags: dict[str, np.ndarray] = {}
    if options.static is not None:
        if roles.id is None:
            raise AocError(f"{param('static')} needs an episode id column to join on: name it with "
                           f"{param('id_column')}")
        static_names, static_feats, static_tags = read_static(
            Path(options.static), roles.static_id, eps.keys, eps.ids,
            bool(np.issubdtype(np.asarray(eps.keys).dtype, np.number)), roles.tags)
    obs_names = list(roles.observations) + static_names
    if not obs_names:
        raise AocError(f"{path}: no observation columns: name them with {param('obs_columns')}, a "
                       f"{param('columns_file')} mapping file or obs_* column names")
    parts = [numeric(cols[c], c, path)[eps.order][:, None] for c in roles.observations]
    if static_feats is not None:
        parts.append(np.repeat(static_feats, np.diff(eps.starts), axis=0))
    observations = np.concatenate(parts, axis=1)
    labelled = text_actions(path, cols, roles.actions, eps.order)  # treatments as text
    if labelled is None:
        act_raw = np.stack([numeric(cols[c], c, path)[eps.order] for c in roles.actions], 1)
        labelled = action_space_of(act_raw, roles.discrete, names=roles.actions)
    actions, act_space = labelled
    terminals, truncations = _flags(path, cols, roles, eps, n)
    tags = _tags(path, cols, roles, eps, static_tags, options.static is not None)
    used = set(roles.observations) | set(roles.actions) | set(roles.tags) | {
        roles.id, roles.time, roles.reward, roles.terminal}
    columns = {c: numeric(cols[c], c, path)[eps.order] for c in header
               if c not in used and is_numeric(cols[c])}
    obs_space = box_space(observations.shape[1], names=obs_names)
    if static_names:
        obs_space["static"] = static_names
    data = CorpusData(
        observations=observations, actions=actions,
        rewards=numeric(cols[roles.reward], roles.reward, path)[eps.order]
        if roles.reward else None,
        terminals=terminals, truncations=truncations, episode_starts=eps.starts,
        observation_space=obs_space, action_space=act_space,
        tags=tags, columns=columns, episode_ids=eps.ids,
        source={"format": "csv", "path": str(path.resolve()),
                "static": str(Path(options.static).resolve()) if options.static else None,
                "roles": {"id": roles.id, "time": roles.time,
                          "observations": roles.observations, "actions": roles.actions,
                          "reward": roles.reward, "terminal": roles.terminal}},
    )
    spec = parse_spec(_mapping(options).get("aoc"), options.columns_file)
    return data if spec is None else restore_exported(data, spec, path)


__all__ = ["read_csv", "read_table", "numeric"]
