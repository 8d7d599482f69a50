"""A clinical cohort table's columns made into a corpus's arrays: the choices the user made at
ingest applied in one place, in order, and recorded as the corpus's ``preprocessing``.

1. Doses cut into dose levels (``--bin-actions``, :mod:`aoc_cli.formats.bins`): checked
   (present, >= 0), the edges fitted, or taken from the corpus appended to or named by
   ``--bin-like``; the raw doses kept as corpus columns.
2. The stay's outcome as the reward of its last step (``--outcome``, ``--outcome-reward``,
   :mod:`aoc_cli.formats.outcomes`); a stay with no outcome, or one the censoring column
   marks, is censored: its last row a truncation.
3. Empty observation cells filled (``--impute``, :mod:`aoc_cli.formats.impute`) with medians
   fitted here, or those of the corpus appended to or named by ``--impute-like``; without a
   rule, empty cells are refused (unless ``--drop-nonfinite`` drops their stays).

:func:`prepare` is also what ``aoc split`` calls to fit both parts on the training stays.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Callable

import numpy as np

from aoc_cli.errors import AocError, param
from aoc_cli.formats import bins as dose_bins
from aoc_cli.formats import impute, outcomes
from aoc_cli.store import discrete_space
from aoc_cli.store.columns import ColumnStack


@dataclass
class Cohort:
    """A table's rows in stay order (N rows, E stays, d observation columns).

    observations (N, d + m) float64: the d columns ``obs_names``, NaN where empty, then room
    for the m ``COL?measured`` features of ``measured`` (:func:`measured_planned`), filled in
    place; or None, the columns given by ``column``; rewards (N,) or None; terminals,
    truncations (N,) bool; doses {column: (N,)} for ``--bin-actions``; outcome (N,) the
    outcome column, NaN where empty; censored (N,) 0/1 the censoring column;
    ``row_label(r)``/``stay_label(e)``: text naming corpus row r / stay e in messages.
    """

    where: str
    starts: np.ndarray
    observations: np.ndarray | None
    obs_names: list[str]
    rewards: np.ndarray | None
    terminals: np.ndarray
    truncations: np.ndarray
    row_label: Callable[[int], str]
    stay_label: Callable[[int], str]
    doses: dict[str, np.ndarray] = field(default_factory=dict)
    outcome: np.ndarray | None = None
    censored: np.ndarray | None = None
    measured: list[str] = field(default_factory=list)
    #: when given (``observations`` None), ``column(j)`` (N,) the raw values of column j,
    #: read once and filled while contiguous (:func:`impute.fill_columns`); the observations
    #: are then a :class:`ColumnStack` of the columns and their ``COL?measured`` features
    column: Callable[[int], np.ndarray] | None = None


def measured_planned(options, names: list[str], gaps) -> list[str]:
    """The ``COL?measured`` features the observations will end with: those of the reused
    imputation, else (``--impute`` with ``--impute-mask``) the columns ``names`` for which
    ``gaps(name)`` is true, else none. Known before the observations are read, so that the
    array is made once, at its full width."""
    spec, _source = _like(options, "impute")
    if spec is not None:
        return impute.planned_measured(spec)
    if options.impute is not None and options.impute_mask:
        return [n for n in names if gaps(n)]
    return []

@dataclass
class Prepared:
    """What :func:`prepare` made: arrays of the corpus and its ``preprocessing``."""

    observations: np.ndarray | None
    obs_names: list[str]
    imputed: np.ndarray | ColumnStack | None
    imputed_cells: dict[str, int]
    rewards: np.ndarray | None
    terminals: np.ndarray
    truncations: np.ndarray
    actions: np.ndarray | None
    action_space: dict | None
    columns: dict[str, np.ndarray]
    preprocessing: dict


def _like(options, key: str) -> tuple[dict | None, str]:
    fitted = options.fitted or {}
    return fitted.get(key), f"corpus {fitted.get('from', {}).get(key, '?')!r}"


def prepare(c: Cohort, options) -> Prepared:
    """The corpus arrays of cohort ``c`` by the ingest ``options``
    (:class:`aoc_cli.formats.ReadOptions`)."""
    pre: dict = {}
    # 1. doses -> dose levels
    actions = action_space = None
    columns: dict[str, np.ndarray] = {}
    if c.doses:
        spec, source = _like(options, "bins")
        asked = dose_bins.parse(options.bin_actions)
        for col, d in c.doses.items():
            dose_bins.check_doses(d, col, c.where, c.row_label)
        if spec is not None:
            dose_bins.check_like(spec, asked, c.where, source)
            pre.setdefault("like", {})["bins"] = source.split("'")[1]
        else:
            spec = dose_bins.fit(c.doses, asked, c.where)
        actions = dose_bins.cut(c.doses, spec)
        labels = dose_bins.labels(spec)
        action_space = discrete_space(len(labels), labels)
        columns.update(c.doses)
        pre["bins"] = spec
    # 2. outcomes -> rewards; censored stays
    rewards = c.rewards
    terminals, truncations = c.terminals.copy(), c.truncations.copy()
    censored = np.zeros(len(c.starts) - 1, bool)
    if c.outcome is not None:
        mapping = outcomes.parse_rewards(options.outcome_reward)
        if mapping is None:
            raise AocError(f"{param('outcome', options.outcome)} needs "
                           f"{param('outcome_reward')} (e.g. 1=-1,0=1): the reward of each "
                           "outcome")
        per_stay = outcomes.stay_outcomes(c.outcome, c.starts, options.outcome, c.where,
                                          c.row_label)
        r = outcomes.outcome_rewards(per_stay, mapping, c.starts, int(c.starts[-1]),
                                     options.outcome, c.where, c.stay_label)
        rewards = r if rewards is None else rewards + r
        censored |= np.isnan(per_stay)
        pre["outcome"] = {"column": options.outcome,
                          "rewards": {f"{k:g}": v for k, v in mapping.items()}}
    elif options.outcome_reward is not None:
        raise AocError(f"{param('outcome_reward')} needs {param('outcome')}: the column "
                       "holding each stay's outcome")
    if c.censored is not None:
        censored |= outcomes.censored_stays(c.censored, c.starts)
        pre["censored_column"] = options.censored_column
    if censored.any():
        outcomes.mark_censored(censored, terminals, truncations, c.starts)
    # 3. empty observation cells
    obs, names, imputed, cells = c.observations, list(c.obs_names), None, {}
    d = len(names)
    spec, source = _like(options, "impute")
    if spec is not None:
        impute.check_like(spec, names, options.impute, options.impute_mask, c.where, source)
        pre.setdefault("like", {})["impute"] = source.split("'")[1]
    elif options.impute_mask and options.impute is None:
        raise AocError(f"{param('impute_mask', True)} needs {param('impute', 'hold')} or "
                       f"{param('impute', 'median')}")
    mask = None
    if c.column is not None and (spec is not None or options.impute is not None):
        rule = spec["rule"] if spec is not None else options.impute
        obs, mask, spec = impute.fill_columns(
            c.column, names, c.starts, rule,
            spec["mask"] if spec is not None else options.impute_mask, list(c.measured),
            c.where, medians=None if spec is None else spec["medians"])
        if _like(options, "impute")[0] is not None:
            spec = _like(options, "impute")[0]  # the reused spec, as it was recorded
    elif c.column is not None:
        obs = ColumnStack([np.asarray(c.column(j), dtype=np.float64) for j in range(d)])
    if mask is None and spec is None and options.impute is not None:
        spec = impute.fit(obs[:, :d], names, options.impute, options.impute_mask, c.where,
                          measured=c.measured if options.impute_mask else None)
    if spec is None and not options.drop_nonfinite:
        impute.refuse_gaps(obs if isinstance(obs, ColumnStack) else obs[:, :d], names,
                           c.where)
    if spec is not None:
        if impute.planned_measured(spec) != list(c.measured):
            raise AssertionError("the observations were made for other measured features")
        if mask is None:
            mask = impute.fill(obs, c.starts, spec)
        names = impute.names_with_mask(spec, names)
        cells = impute.counts(mask, names)
        imputed = mask if mask.any() else None
        pre["impute"] = spec
    return Prepared(obs, names, imputed, cells, rewards, terminals, truncations, actions,
                    action_space, columns, pre)
