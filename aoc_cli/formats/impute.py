"""Empty observation cells of a clinical table, filled by a rule the user chose and recorded.

A cohort table holds gaps: a lab drawn once a day leaves five of six 4-hour blocs empty. Each
rule is a choice the corpus records (``preprocessing["impute"]``), with the statistics it was
fitted on:

* ``hold``: the last measured value within the stay (carried forward), else the column's
  median;
* ``median``: the column's median.

The medians are those of the corpus's own measured cells (``fit``). Data appended to the
corpus, a held-out log ingested ``--impute-like`` it, the test part of a split, and an
``explain`` query holding ``null`` are filled with the corpus's medians (``fill``), never
with their own: nothing of held-out data leaks into what the corpus was fitted on. With
``mask``, every column with gaps adds a 0/1 feature ``COL?measured`` to the observation.
Which cells were filled is kept (``Corpus.imputed_mask``) and counted per column.
Actions and rewards are never imputed.
"""

from __future__ import annotations

import os
from concurrent.futures import ThreadPoolExecutor

import numpy as np

from aoc_cli.errors import AocError, param
from aoc_cli.store.columns import ColumnStack

RULES = ("hold", "median")
#: Suffix of the 0/1 feature that says whether a column was measured.
MEASURED = "?measured"


def refuse_gaps(obs: np.ndarray | ColumnStack, names: list[str], where) -> None:
    """An AocError naming the share of empty cells in the worst columns and the flags, when
    (N, d) ``obs`` (or the first d columns of a ColumnStack) holds NaN; nothing otherwise."""
    cols = obs.columns[:len(names)] if isinstance(obs, ColumnStack) else obs.T
    empty = np.array([np.isnan(c).mean() for c in cols]) if len(obs) else \
        np.zeros(len(names))
    if not empty.any():
        return
    worst = np.argsort(-empty, kind="stable")[:3]
    parts = [f"{names[j]!r} {100 * empty[j]:.1f}%" for j in worst if empty[j] > 0]
    gaps = int((empty > 0).sum())
    raise AocError(f"{where}: {gaps} observation column{'s' if gaps > 1 else ''} "
                   f"{'have' if gaps > 1 else 'has'} empty cells (worst: {', '.join(parts)}): "
                   f"choose how to fill them with {param('impute', 'hold')} or "
                   f"{param('impute', 'median')} (add {param('impute_mask', True)} for "
                   f"'measured' features), or drop those stays with "
                   f"{param('drop_nonfinite', True)}")


def fit(obs: np.ndarray, names: list[str], rule: str, mask: bool, where,
        measured: list[str] | None = None) -> dict:
    """The imputation of (N, d) ``obs`` (NaN: empty): ``{"rule", "mask", "names",
    "medians", "measured"}``, ``measured`` the columns with gaps (given, or found), one
    ``COL?measured`` feature each with ``mask``. A column empty for every row is an
    AocError."""
    if rule not in RULES:
        raise AocError(f"unknown {param('impute', rule)}: use one of {', '.join(RULES)}")
    medians, gaps = [], []
    for j, name in enumerate(names):
        col = obs[:, j]
        present = col[~np.isnan(col)]
        if present.size == 0:
            raise AocError(f"{where}: column {name!r} is empty for every stay: "
                           f"{param('impute', rule)} has no measured value to fill it from; "
                           "drop the column")
        medians.append(float(np.median(present)))
        if present.size < len(col):
            gaps.append(name)
    return {"rule": rule, "mask": bool(mask), "names": list(names), "medians": medians,
            "measured": list(gaps if measured is None else measured)}


def check_like(spec: dict, names: list[str], rule: str | None, mask: bool, where,
               source: str) -> None:
    """The data to fill has the columns ``spec`` was fitted on, and no other rule asked."""
    if list(spec["names"]) != list(names):
        raise AocError(f"{where}: its observation columns {names} differ from those "
                       f"{source} was imputed on {spec['names']}")
    if rule is not None and rule != spec["rule"]:
        raise AocError(f"{where}: {param('impute', rule)} differs from the rule "
                       f"{spec['rule']!r} of {source}: drop it (the corpus's rule applies)")
    if mask and not spec["mask"]:
        raise AocError(f"{where}: {param('impute_mask', True)} but {source} has no "
                       "'measured' features: drop it")


def planned_measured(spec: dict | None) -> list[str]:
    """The ``COL?measured`` features a fitted ``spec`` adds (none without its mask)."""
    return list(spec["measured"]) if spec and spec.get("mask") else []


def fill(obs: np.ndarray, starts: np.ndarray, spec: dict) -> np.ndarray:
    """Fill ``obs`` (N, d + m) in place and return the imputed cells (N, d + m) bool.

    The first d = ``len(spec["names"])`` columns hold the values, NaN where empty; each empty
    cell takes, by ``spec["rule"]``, the last measured value of its column within its stay
    (``hold``; the stays: ``starts`` (E + 1,)) or else the column's median. The m trailing
    columns receive the 0/1 ``COL?measured`` features of ``spec["measured"]`` (with
    ``spec["mask"]``; never imputed themselves). Column by column: a few (N,) temporaries."""
    names, d = spec["names"], len(spec["names"])
    features = {name: d + k for k, name in enumerate(planned_measured(spec))}
    imputed = np.zeros(obs.shape, bool)
    stay_start = np.repeat(starts[:-1], np.diff(starts)) if spec["rule"] == "hold" else None
    for j in range(d):
        col = obs[:, j]
        empty = np.isnan(col)
        if names[j] in features:
            obs[:, features[names[j]]] = ~empty
        if not empty.any():
            continue
        imputed[:, j] = empty
        _fill_column(col, empty, stay_start, spec["medians"][j])
    return imputed


def _filled(x: np.ndarray, name: str, stay_start: np.ndarray | None, rule: str, where,
            median: float | None) -> tuple:
    """(one column ``x`` filled, its empty cells or None when it has none, the median used:
    ``median``, else that of its measured cells) as :func:`fill_columns` keeps them."""
    empty = np.isnan(x)
    any_empty = bool(empty.any())
    if median is None:
        present = x[~empty] if any_empty else x
        if present.size == 0:
            raise AocError(f"{where}: column {name!r} is empty for every stay: "
                           f"{param('impute', rule)} has no measured value to fill it from; "
                           "drop the column")
        # partitioned in place when ``present`` is a copy already
        median = float(np.median(present, overwrite_input=any_empty))
    if not any_empty:
        return x, None, median
    if not x.flags.writeable:
        x = x.copy()
    _fill_column(x, empty, stay_start, median)
    return x, empty, median


def _fill_column(x: np.ndarray, empty: np.ndarray, stay_start: np.ndarray | None,
                 median: float) -> None:
    """Fill the empty cells of one column ``x`` (N,) in place: with ``stay_start`` (N,) (the
    ``hold`` rule) the last measured value at or before each row within its stay, else (and
    where the stay has none yet) the ``median``. The last measured row before each empty one
    is found by a binary search of the measured rows, on the empty rows only (~15% of a
    cohort's cells: a quarter faster than a running maximum of every row's index)."""
    holes = np.flatnonzero(empty)
    if stay_start is None:
        x[holes] = median
        return
    measured = np.flatnonzero(~empty)
    before = np.searchsorted(measured, holes) - 1  # -1: none before it
    last = measured[np.maximum(before, 0)] if len(measured) else np.zeros(len(holes), int)
    held = (before >= 0) & (last >= stay_start[holes])
    x[holes[held]] = x[last[held]]
    x[holes[~held]] = median


def fill_columns(column, names: list[str], starts: np.ndarray, rule: str, mask: bool,
                 measured: list[str], where, medians: list[float] | None = None
                 ) -> tuple[ColumnStack, np.ndarray, dict]:
    """:func:`fit` (unless ``medians`` are given) and :func:`fill` in one pass, column by
    column: ``column(j)`` (N,) float64, NaN where empty, is filled while contiguous (the
    columns on the machine's cores: each is its own) and kept as a column, with its
    ``COL?measured`` feature (bool). Returns (the observations: a
    :class:`ColumnStack` of the d filled columns then the m features of ``measured``, the
    imputed cells (N, d + m) as a bool ColumnStack, the spec) as :func:`fit` and :func:`fill`
    would make them; a column empty for every row is an AocError."""
    if rule not in RULES:
        raise AocError(f"unknown {param('impute', rule)}: use one of {', '.join(RULES)}")
    d, n = len(names), int(starts[-1])
    features = {name: k for k, name in enumerate(measured if mask else [])}
    stay_start = np.repeat(starts[:-1], np.diff(starts)) if rule == "hold" else None

    def one(j: int, x: np.ndarray):
        return _filled(x, names[j], stay_start, rule, where,
                       None if medians is None else medians[j])

    raw = [np.asarray(column(j), dtype=np.float64) for j in range(d)]  # read here, in order
    # columns are independent and numpy lets go of the GIL: filled on the cores (<= 4)
    with ThreadPoolExecutor(max_workers=max(1, min(4, os.cpu_count() or 1))) as pool:
        done = list(pool.map(one, range(d), raw))  # the first failing column's error
    del raw
    values = [x for x, _e, _m in done]
    empties = [e for _x, e, _m in done]  # each column's empty cells (None: none)
    fitted = [m for _x, _e, m in done]
    gaps = [name for name, e in zip(names, empties) if e is not None]
    unknown = [m for m in features if m not in names]
    if unknown:
        raise AssertionError(f"measured features of columns that are not read: {unknown}")
    none = np.zeros(n, bool)  # one array for every column without gaps
    cells = [none if e is None else e for e in empties]
    measured_of = [cells[names.index(m)] for m in features]
    # the features are ~empty and never imputed: the same arrays, negated / not at all
    observations = ColumnStack(values + measured_of, negate=[False] * d + [True] * len(features))
    imputed = ColumnStack(cells + [none] * len(features), dtype=bool)
    spec = {"rule": rule, "mask": bool(mask), "names": list(names),
            "medians": list(fitted if medians is None else medians),
            "measured": list(measured if mask else gaps)}
    return observations, imputed, spec


def names_with_mask(spec: dict | None, names: list[str]) -> list[str]:
    """Observation names after filling: ``names`` plus ``COL?measured`` features."""
    if not spec or not spec.get("mask"):
        return list(names)
    return list(names) + [n + MEASURED for n in spec["measured"]]


def counts(imputed: np.ndarray | ColumnStack, names: list[str]) -> dict[str, int]:
    """Imputed cells per column (the columns with any)."""
    per = imputed.column_sums() if isinstance(imputed, ColumnStack) else imputed.sum(axis=0)
    return {n: int(c) for n, c in zip(names, per) if c}


def fill_query(obs: np.ndarray, spec: dict, previous: np.ndarray | None = None) -> np.ndarray:
    """(Q, d) query observations whose unmeasured cells are NaN (``null`` in JSON) -> filled
    by the corpus's rule: ``hold`` the query's ``previous`` observation (its history's last
    step, itself filled) where given, else the corpus's medians; and the ``COL?measured``
    features set (0 where the cell was null) when the corpus has them; a query already of the
    corpus's full width has its NaN cells filled and its given measured features kept."""
    d = len(spec["names"])
    obs = np.asarray(obs, dtype=np.float64)
    base = obs[:, :d]
    empty = np.isnan(base)
    fallback = np.asarray(spec["medians"], dtype=np.float64)[None, :]
    if spec["rule"] == "hold" and previous is not None:
        fallback = np.asarray(previous, dtype=np.float64)[None, :d]
    filled = np.where(empty, fallback, base)
    if not spec.get("mask") or not spec["measured"]:
        return filled
    cols = [spec["names"].index(n) for n in spec["measured"]]
    if obs.shape[1] == d + len(cols):
        given = obs[:, d:]
        measured = np.where(np.isnan(given), (~empty[:, cols]).astype(float), given)
    else:
        measured = (~empty[:, cols]).astype(float)
    return np.concatenate([filled, measured], axis=1)
