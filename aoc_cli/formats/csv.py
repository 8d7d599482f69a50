"""Tabular logs (the healthcare case): one row per time step, from a CSV (plain or gzip), a
Parquet file, or in Python an Arrow table or a pandas / polars DataFrame.

Column roles come from flags (or the same keyword arguments), else a small JSON mapping file
(``--columns FILE``), else the defaults:

==============  ==============================  =====================================
role            mapping key                     default
==============  ==============================  =====================================
episode id      ``id``                          ``episode``, else ``id``, else one episode
time            ``time``                        ``t``, else ``time``, else file order
observations    ``observations`` (names/globs)  ``obs_*``
actions         ``actions`` (names/globs)       ``act_*`` (the ``--bin-actions`` columns)
reward          ``reward``                      ``reward`` if present
terminal flag   ``terminal``                    the last row of every episode
tag columns     ``tags`` (list)                 none
discrete        ``discrete_actions`` (bool)     false
static id       ``static_id``                   the episode id column's name
==============  ==============================  =====================================

A column of another role (the outcome, reward, an action, the censoring or terminal flag, the
episode id, the time) named among the observations is refused, as it would leak into the state
(:class:`aoc_cli.errors.RoleOverlap`; ``allow_role_overlap`` keeps it); the default ``obs_*``
columns and a static file's columns leave such a column out.

The table is read by pyarrow (:mod:`aoc_cli.formats.table`) and converted to numpy column by
column, once. Rows are ordered by episode id and time whatever the file's order (ids
numerically when they are all numbers; times as numbers or ISO dates); two rows of one episode
at the same time are an error naming them. The episode ids are kept. A second table of static
per-episode features (``--static FILE``, one row per id) is joined onto every step and appended
to the observation: numeric columns as they are, text columns one-hot (``sex=F``, ``sex=M``);
the names are recorded in the observation space's ``names`` and ``static``
(:mod:`aoc_cli.formats.static`). Action columns holding text (``oxygen``, ``none``) are
discrete actions whose labels are kept (:mod:`aoc_cli.formats.text_actions`). Remaining numeric
columns are kept as corpus columns (usable as value targets).

A clinical cohort table adds (each recorded in the corpus's ``preprocessing``): empty cells
filled by ``--impute`` (:mod:`aoc_cli.formats.impute`), continuous doses cut into dose levels
at their quantiles or at a study's own levels by ``--bin-actions``
(:mod:`aoc_cli.formats.bins`), the stay's outcome as its last reward and
censored stays (:mod:`aoc_cli.formats.outcomes`).

A CSV of ``aoc export`` is read back exactly with the mapping beside it
(:mod:`aoc_cli.formats.csv_exported`).
"""

from __future__ import annotations

import fnmatch
import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pyarrow as pa

from aoc_cli.errors import AocError, RoleOverlap, param
from aoc_cli.formats.bins import parse as parse_bins
from aoc_cli.formats.cohort import Cohort, measured_planned, prepare
from aoc_cli.formats.common import ReadOptions, action_space_of, encode_labels
from aoc_cli.formats.csv_exported import exported_mapping, restore_exported
from aoc_cli.formats.episodes import Episodes, order_episodes
from aoc_cli.formats.spec import parse_spec
from aoc_cli.formats.static import read_static
from aoc_cli.formats.table import (Table, from_frame, has_gaps, is_numeric, numeric,
                                   read_table, text)
from aoc_cli.formats.text_actions import text_actions
from aoc_cli.store import CorpusData

MAPPING_KEYS = {"id", "time", "observations", "actions", "reward", "terminal", "tags",
                "discrete_actions", "static_id", "static", "aoc"}


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


def _match(header: list[str], patterns, role: str, where) -> list[str]:
    """Columns named by ``patterns`` (names or globs), in file order for globs."""
    patterns = [patterns] if isinstance(patterns, str) else list(patterns)
    out: list[str] = []
    for p in patterns:
        hits = [h for h in header if fnmatch.fnmatchcase(h, p)] if any(
            c in p for c in "*?[") else ([p] if p in header else [])
        if not hits:
            raise AocError(f"{where}: no column matches {role} {p!r} (columns: "
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


def _text_columns(options: ReadOptions) -> list[str]:
    """Columns read as text whatever they hold: the possible id and the tag columns."""
    m = _mapping(options)
    return [c for c in (options.id_column, m.get("id"), "episode", "id", *options.tag_columns,
                        *m.get("tags", [])) if c]


def _roles(where, header: list[str], options: ReadOptions, bins: list[str] | None) -> Roles:
    """Column roles from the flags, else the mapping file, else the defaults."""
    m = _mapping(options)
    id_col = options.id_column or m.get("id") or _first_present(header, ("episode", "id"))
    time_col = options.time_column or m.get("time") or _first_present(header, ("t", "time"))
    for role, col in (("episode id", id_col), ("time", time_col),
                      ("outcome", options.outcome), ("censoring", options.censored_column)):
        if col is not None and col not in header:
            raise AocError(f"{where}: no {role} column {col!r} (columns: {', '.join(header)})")
    named = options.obs_columns or m.get("observations")
    obs_cols = _match(header, named, "observation column", where) if named else \
        [h for h in header if fnmatch.fnmatchcase(h, "obs_*")]
    if bins:
        act_cols = _match(header, bins, "dose column", where)
        asked = options.act_columns or m.get("actions")
        if asked and _match(header, asked, "action column", where) != act_cols:
            raise AocError(f"{param('act_columns')} and {param('bin_actions')} name different "
                           "columns: the binned doses are the actions")
    else:
        act_cols = _match(header, options.act_columns or m.get("actions") or "act_*",
                          "action column", where)
    reward_col = None
    if not options.reward_free:
        reward_col = options.reward_column or (m["reward"] if "reward" in m else (
            "reward" if "reward" in header else None))  # a mapping's null: no reward
        if reward_col is not None and reward_col not in header:
            raise AocError(f"{where}: no reward column {reward_col!r}: name it with "
                           f"{param('reward_column')} or pass {param('reward_free')}")
    term_col = options.terminal_column or m.get("terminal")
    if term_col is not None and term_col not in header:
        raise AocError(f"{where}: no terminal column {term_col!r}")
    role_cols = _role_columns(options, id_col, time_col, act_cols, reward_col, term_col,
                              bool(bins))
    obs_cols = _observations(where, obs_cols, bool(named), options, role_cols)
    discrete = options.discrete_actions or bool(m.get("discrete_actions", False))
    if discrete and len(act_cols) != 1:
        raise AocError(f"{param('discrete_actions')} needs exactly one action column, got "
                       f"{act_cols}")
    return Roles(id_col, time_col, obs_cols, act_cols, reward_col, term_col,
                 list(options.tag_columns) or list(m.get("tags", [])), discrete,
                 m.get("static_id") or id_col)


def _role_columns(options: ReadOptions, id_col, time_col, act_cols, reward_col, term_col,
                  binned: bool) -> dict[str, tuple[str, str, str]]:
    """{column: (its role, the parameter naming it, what listing it as an observation
    would do)} for the columns of a role that must not be an observation."""
    out: dict[str, tuple[str, str, str]] = {}
    for col, role, name, harm in (
            (options.outcome, "the outcome", "outcome", "the outcome would leak into the state"),
            (reward_col, "the reward", "reward_column", "the reward would leak into the state"),
            *((c, "an action", "bin_actions" if binned else "act_columns",
               "the action would leak into the state it is chosen in") for c in act_cols),
            (options.censored_column, "the censoring flag", "censored_column",
             "the censoring would leak into the state"),
            (term_col, "the terminal flag", "terminal_column",
             "the stay's end would leak into the state"),
            (id_col, "the stay id", "id_column", "the stay's id would become a feature"),
            (time_col, "the time", "time_column", "the time would become a feature")):
        if col is not None:
            out.setdefault(col, (role, name, harm))
    return out


def _observations(where, obs_cols: list[str], named: bool, options: ReadOptions,
                  role_cols: dict) -> list[str]:
    """The observation columns ``obs_cols``: when ``named`` (flag or mapping), a column of
    another role among them is refused unless ``allow_role_overlap``; the default ones
    (``obs_*``) are those that play no other role."""
    if options.allow_role_overlap:
        return obs_cols
    if not named:
        return [h for h in obs_cols if h not in role_cols]
    overlap = [c for c in obs_cols if c in role_cols]
    if overlap:
        col = overlap[0]
        role, name, harm = role_cols[col]
        source = param("obs_columns") if options.obs_columns else \
            f"the observations of {param('columns_file')}"
        raise RoleOverlap(
            f"{where}: column {col!r} is {role} ({param(name)}) and an observation "
            f"({source}): {harm}; drop it from the observations, or pass "
            f"{param('allow_role_overlap', True)}", column=col, role=name)
    return obs_cols


def _flags(table: Table, roles: Roles, eps: Episodes):
    """(terminals, truncations) (N,): each episode's last row ends it, a terminal unless the
    terminal column says otherwise (then a truncation)."""
    n = table.n
    terminals = np.zeros(n, bool)
    truncations = np.zeros(n, bool)
    last = eps.starts[1:] - 1
    if roles.terminal is None:
        terminals[last] = True
    else:
        terminals = eps.take(numeric(table.cols[roles.terminal], roles.terminal, table.where,
                                     eps.row_label)) != 0
        truncations[last] = ~terminals[last]
    return terminals, truncations


def _tags(table: Table, roles: Roles, eps: Episodes, static_tags: dict,
          has_static: bool) -> dict:
    lengths = np.diff(eps.starts)
    tags = {}
    for c in roles.tags:
        if c in table.cols:
            tags[c] = encode_labels(eps.take(text(table.cols[c])))
        elif c in static_tags:
            tags[c] = encode_labels(np.repeat(static_tags[c], lengths))
        else:
            raise AocError(f"{param('tag_columns')} {c!r} is not a column of {table.where}"
                           + (f" or of the {param('static')} file" if has_static else ""))
    return tags


def read_csv(path: Path, options: ReadOptions) -> CorpusData:
    """Read a CSV or Parquet log (and ``options.static``) into a corpus."""
    path = Path(path)
    options = exported_mapping(path, options)
    table = read_table(path, options.progress, text_columns=_text_columns(options))
    data = read_columns(table, options, {"path": str(path.resolve())})
    spec = parse_spec(_mapping(options).get("aoc"), options.columns_file)
    return data if spec is None else restore_exported(data, spec, path)


def read_frame(frame, options: ReadOptions) -> CorpusData:
    """Read an Arrow table or a pandas / polars DataFrame (and ``options.static``)."""
    table = from_frame(frame, text_columns=_text_columns(options))
    return read_columns(table, options, {"path": None, "frame": type(frame).__name__})


def read_columns(table: Table, options: ReadOptions, source: dict) -> CorpusData:
    """The corpus of a table's columns (roles by ``options``)."""
    where, cols = table.where, table.cols
    bins = options.fitted.get("bins")
    bin_cols = list(bins["columns"]) if bins else None
    if options.bin_actions is not None and bin_cols is None:
        bin_cols = list(parse_bins(options.bin_actions))
    roles = _roles(where, table.header, options, bin_cols)
    if table.n == 0:
        raise AocError(f"{where} has zero rows: nothing to store")
    eps = order_episodes(table, roles.id, roles.time)
    static_names: list[str] = []
    static_feats = None
    static_tags: dict[str, np.ndarray] = {}
    if options.static is not None:
        if roles.id is None:
            raise AocError(f"{param('static')} needs an episode id column to join on: name it "
                           f"with {param('id_column')}")
        static_names, static_feats, static_tags = read_static(
            Path(options.static), roles.static_id, eps.keys, eps.ids,
            bool(np.issubdtype(np.asarray(eps.keys).dtype, np.number)), roles.tags,
            skip=set() if options.allow_role_overlap else {
                roles.id, roles.time, roles.reward, roles.terminal, options.outcome,
                options.censored_column, *roles.actions} - {None})
    obs_names = list(roles.observations) + static_names
    if not obs_names:
        raise AocError(f"{where}: no observation columns: name them with "
                       f"{param('obs_columns')}, a {param('columns_file')} mapping file or "
                       "obs_* column names")
    static_gaps = dict(zip(static_names, np.isnan(static_feats).any(axis=0))) \
        if static_feats is not None else {}
    measured = measured_planned(options, obs_names, lambda c: static_gaps[c]
                                if c in static_gaps else has_gaps(cols[c]))
    # each table column dropped once read: its values kept as one column (memory: one copy)
    other_roles = set(roles.tags) | set(roles.actions) | {
        roles.id, roles.time, roles.reward, roles.terminal, options.outcome,
        options.censored_column}

    def column(j: int) -> np.ndarray:
        """Observation column j in stay order, read once (its table column then dropped)."""
        if j >= len(roles.observations):  # a static feature, per stay
            return np.repeat(static_feats[:, j - len(roles.observations)], np.diff(eps.starts))
        c = roles.observations[j]
        x = eps.take(numeric(cols[c], c, where, eps.row_label))
        if c not in other_roles:
            del cols[c]
        return x

    terminals, truncations = _flags(table, roles, eps)
    cohort = Cohort(
        where=where, starts=eps.starts, observations=None, obs_names=obs_names,
        rewards=eps.take(numeric(cols[roles.reward], roles.reward, where, eps.row_label))
        if roles.reward else None,
        terminals=terminals, truncations=truncations, row_label=eps.corpus_row_label,
        stay_label=lambda e: f"{roles.id or 'episode'} {eps.ids[e]}", measured=measured,
        column=column)
    if bin_cols:
        cohort.doses = {c: eps.take(numeric(cols[c], c, where, eps.row_label))
                        for c in roles.actions}
        actions, act_space = None, None
    else:
        labelled = text_actions(where, cols, roles.actions, eps.order, eps.row_label)
        if labelled is None:
            act_raw = np.stack([eps.take(numeric(cols[c], c, where, eps.row_label))
                                for c in roles.actions], 1)
            labelled = action_space_of(act_raw, roles.discrete, names=roles.actions)
        actions, act_space = labelled
    for role, c in (("outcome", options.outcome), ("censored", options.censored_column)):
        if c is not None:
            setattr(cohort, role, _truthy(cols[c]) if role == "censored" else
                    numeric(cols[c], c, where, eps.row_label))
            setattr(cohort, role, eps.take(getattr(cohort, role)))
    prepared = prepare(cohort, options)
    tags = _tags(table, roles, eps, static_tags, options.static is not None)
    used = set(roles.observations) | set(roles.actions) | set(roles.tags) | {
        roles.id, roles.time, roles.reward, roles.terminal, options.censored_column}
    columns = {c: eps.take(numeric(cols[c], c, where)) for c in table.header
               if c not in used and c in cols and is_numeric(cols[c])}
    columns.update(prepared.columns)
    if actions is None:
        actions, act_space = prepared.actions, prepared.action_space
    obs_space = {"type": "box", "shape": [prepared.observations.shape[1]],
                 "names": prepared.obs_names}
    if static_names:
        obs_space["static"] = static_names
    return CorpusData(
        observations=prepared.observations, actions=actions, rewards=prepared.rewards,
        terminals=prepared.terminals, truncations=prepared.truncations,
        episode_starts=eps.starts, observation_space=obs_space, action_space=act_space,
        tags=tags, columns=columns, episode_ids=eps.ids, imputed=prepared.imputed,
        preprocessing=prepared.preprocessing,
        source={"format": "csv", **source,
                "static": str(Path(options.static).resolve()) if options.static else None,
                "roles": {"id": roles.id, "time": roles.time,
                          "observations": roles.observations, "actions": roles.actions,
                          "reward": roles.reward, "terminal": roles.terminal,
                          **({"outcome": options.outcome} if options.outcome else {}),
                          **({"censored": options.censored_column}
                             if options.censored_column else {})},
                **({"imputed_cells": prepared.imputed_cells} if prepared.imputed_cells
                   else {})},
    )


def _truthy(col: pa.ChunkedArray) -> np.ndarray:
    """(N,) float 0/1: a censoring column's cells (numbers: non-zero; text: anything but
    empty, 0, false, no)."""
    if is_numeric(col):
        return np.nan_to_num(numeric(col, "", ""), nan=0.0)
    cells = np.char.lower(text(col))
    return (~np.isin(cells, ["", "0", "false", "no", "f", "n"])).astype(np.float64)


__all__ = ["read_columns", "read_csv", "read_frame", "read_table", "numeric"]
