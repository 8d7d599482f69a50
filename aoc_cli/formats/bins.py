"""Continuous doses cut into the usual dose levels (the AI Clinician's 5 x 5 scheme,
Komorowski et al. 2018): ``--bin-actions input_4hourly=5,max_dose_vaso=5``.

For a column cut into ``n`` bins, a zero dose is bin 0 and the non-zero doses are cut at their
quantiles ``1/(n-1), ..., (n-2)/(n-1)`` into bins 1 .. n-1. A study's own levels are given
instead as the lower edge of each non-zero bin, ``input_4hourly=0:50:180:530`` (bins 0, 0-50,
50-180, 180-530, 530 and more; a dose equal to an edge falls in the bin it opens): they are
used as they are, never fitted (``"given"`` lists those columns; their last edge is None, the
top bin open). The edges are stored with the corpus (``preprocessing["bins"]``): data appended
to it, a log ingested ``--bin-like`` it and the test part of a split are cut at the same edges
(a dose beyond the fitted range falls in the first or last non-zero bin; ``aoc split`` fits
the counted columns again on its training part and keeps the given edges). Several binned columns make one discrete action per combination, the first
column varying slowest; each action is labelled with its ranges, ``input_4hourly 2/5
(50-180), max_dose_vaso 0/5 (0)``. The raw doses are kept as corpus columns of the same names,
so the bins can be fitted again (``aoc split``).
"""

from __future__ import annotations

import itertools

import numpy as np

from aoc_cli.errors import AocError, param


#: How to write ``--bin-actions``, for its errors.
_FORMS = ("COLUMN=BINS (BINS >= 2: cut at the doses' quantiles) or COLUMN=0:EDGE:EDGE... (the "
          "lower edge of each non-zero bin, increasing), comma-separated, e.g. "
          "input_4hourly=5,max_dose_vaso=0:0.08:0.22:0.45")


def parse(text: str | dict | None) -> dict[str, int | list[float]] | None:
    """``"input_4hourly=5,max_dose_vaso=0:0.08:0.22:0.45"`` (or a dict of counts, edge lists
    or such texts) -> {column: bins (a count to fit) or the given lower edges of the non-zero
    bins}."""
    if text is None:
        return None
    if isinstance(text, dict):
        return {str(k): _value(str(k), v, f"{k}={v}") for k, v in text.items()}
    out: dict[str, int | list[float]] = {}
    for part in [p.strip() for p in text.split(",") if p.strip()]:
        col, eq, value = part.partition("=")
        if not col.strip() or not eq:
            raise AocError(f"{param('bin_actions', text)}: write {_FORMS}")
        out[col.strip()] = _value(col.strip(), value.strip(), part)
    return out


def _value(col: str, value, part: str) -> int | list[float]:
    """One column's bins: a count >= 2, or its given edges (checked: :func:`check_edges`)."""
    if isinstance(value, (list, tuple)) or (isinstance(value, str) and ":" in value):
        return check_edges(col, value.split(":") if isinstance(value, str) else value, part)
    try:
        bins = int(value)
    except (TypeError, ValueError):
        bins = 0
    if bins < 2 or isinstance(value, float) and value != bins:
        raise AocError(f"{param('bin_actions', part)}: write {_FORMS}")
    return bins


def check_edges(col: str, values, part: str) -> list[float]:
    """The given lower edges of column ``col``'s non-zero bins as floats: at least two, each
    a finite number >= 0, increasing; else an AocError naming the column."""
    bad = f"{param('bin_actions', part)}: the dose levels of {col!r} "
    edges = []
    for v in values:
        try:
            x = float(str(v).strip()) if not isinstance(v, (int, float)) else float(v)
        except ValueError:
            x = float("nan")
        if isinstance(v, bool) or not np.isfinite(x):
            raise AocError(f"{bad}hold {str(v).strip()!r}, not a number: give the lower edge "
                           "of each non-zero bin, e.g. 0:50:180:530")
        edges.append(x)
    if len(edges) < 2:
        raise AocError(f"{bad}need at least two edges (0:CUT: bin 1 from 0 to CUT, bin 2 from "
                       "CUT on), e.g. 0:50:180:530")
    if edges[0] < 0:
        raise AocError(f"{bad}start at {edges[0]:g}, a negative dose: doses are >= 0, start "
                       "the edges at 0, e.g. 0:50:180:530")
    step = next((i for i in range(1, len(edges)) if edges[i] <= edges[i - 1]), None)
    if step is not None:
        raise AocError(f"{bad}do not increase ({edges[step - 1]:g} then {edges[step]:g}): give "
                       "each non-zero bin's lower edge in increasing order, e.g. 0:50:180:530")
    return edges


def asked_of(spec: dict) -> dict[str, int | list[float]]:
    """What a stored spec was asked for: {column: bins, or its given edges}."""
    given = spec.get("given", [])
    return {c: list(spec["edges"][c][:-1]) if c in given else int(n)
            for c, n in zip(spec["columns"], spec["bins"])}


def describe(bins: dict[str, int | list[float]]) -> str:
    """``input_4hourly=5,max_dose_vaso=0:0.08:0.22:0.45``: the bins as ``--bin-actions``
    writes them."""
    return ",".join(f"{c}={':'.join(f'{x:g}' for x in n) if isinstance(n, list) else n}"
                    for c, n in bins.items())


def check_doses(doses: np.ndarray, name: str, where, row_label) -> None:
    """Every dose present and >= 0; else an AocError naming the row and its stay.
    ``row_label(i)``: text naming row i and its stay (``data row 7 (icustayid 3)``)."""
    empty = np.flatnonzero(np.isnan(doses))
    if empty.size:
        i = int(empty[0])
        raise AocError(f"{where}: dose column {name!r}, {row_label(i)} is empty: every step "
                       "needs its dose (0 when none was given; doses are never imputed)")
    neg = np.flatnonzero(doses < 0)
    if neg.size:
        i = int(neg[0])
        raise AocError(f"{where}: dose column {name!r}, {row_label(i)} holds {doses[i]:g}, a "
                       "negative dose: fix the data")


def fit(doses: dict[str, np.ndarray], bins: dict[str, int | list[float]], where) -> dict:
    """``{"columns": [...], "bins": [...], "edges": {col: [low, cut..., high]}}`` from the
    doses (N,) of each column: ``low``/``high`` the smallest and largest non-zero dose, the
    cuts their quantiles; a column whose edges are given (a list) keeps them, its ``high``
    None (the top bin open), and is listed in ``"given"``."""
    edges = {}
    counts = []
    for col, n in bins.items():
        if isinstance(n, list):
            edges[col] = [float(x) for x in n] + [None]
            counts.append(len(n) + 1)
            continue
        counts.append(int(n))
        nonzero = doses[col][doses[col] > 0]
        distinct = np.unique(nonzero)
        if len(distinct) < n - 1:
            raise AocError(f"{where}: {param('bin_actions', f'{col}={n}')} needs at least "
                           f"{n - 1} distinct non-zero doses of {col!r} for its {n - 1} "
                           f"non-zero bins, the data hold {len(distinct)}: use fewer bins")
        cuts = np.quantile(nonzero, np.arange(1, n - 1) / (n - 1)) if n > 2 else []
        edges[col] = [float(distinct[0]), *map(float, cuts), float(distinct[-1])]
    spec = {"columns": list(bins), "bins": counts, "edges": edges}
    given = [c for c, n in bins.items() if isinstance(n, list)]
    return {**spec, "given": given} if given else spec


def cut(doses: dict[str, np.ndarray], spec: dict) -> np.ndarray:
    """(N,) discrete action: the combination of each column's bin, first column slowest."""
    codes = None
    for col, n in zip(spec["columns"], spec["bins"]):
        inner = np.asarray(spec["edges"][col][1:-1], dtype=np.float64)
        d = doses[col]
        level = np.where(d > 0, 1 + np.searchsorted(inner, d, side="right"), 0)
        codes = level if codes is None else codes * n + level
    return codes.astype(np.int64)


def _fmt(x: float) -> str:
    return f"{x:.3g}" if abs(x) < 1000 else f"{x:.0f}"


def labels(spec: dict) -> list[str]:
    """The label of each action: ``input_4hourly 2/5 (50-180), max_dose_vaso 0/5 (0)``."""
    per_col = []
    for col, n in zip(spec["columns"], spec["bins"]):
        e = spec["edges"][col]
        names = [f"{col} 0/{n} (0)"]
        names += [f"{col} {j}/{n} ({_fmt(e[j - 1])}-{_fmt(e[j])})" if e[j] is not None
                  else f"{col} {j}/{n} ({_fmt(e[j - 1])}+)" for j in range(1, n)]
        per_col.append(names)
    return [", ".join(combo) for combo in itertools.product(*per_col)]


def check_like(spec: dict, bins: dict[str, int | list[float]] | None, where,
               source: str) -> None:
    """``--bin-actions`` given with ``--bin-like`` or ``--append`` must agree with the edges."""
    stored = asked_of(spec)
    if bins is not None and (list(bins) != list(stored) or list(bins.values()) !=
                             list(stored.values())):
        raise AocError(f"{where}: {param('bin_actions')} differs from the bins of {source} "
                       f"({describe(stored)}): drop it (the corpus's edges apply)")
