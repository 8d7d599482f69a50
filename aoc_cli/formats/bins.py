"""Continuous doses cut into the usual dose levels (the AI Clinician's 5 x 5 scheme,
Komorowski et al. 2018): ``--bin-actions input_4hourly=5,max_dose_vaso=5``.

For a column cut into ``n`` bins, a zero dose is bin 0 and the non-zero doses are cut at their
quantiles ``1/(n-1), ..., (n-2)/(n-1)`` into bins 1 .. n-1. The edges are stored with the corpus
(``preprocessing["bins"]``): data appended to it, a log ingested ``--bin-like`` it and the test
part of a split are cut at the same edges (a dose beyond the fitted range falls in the first or
last non-zero bin). Several binned columns make one discrete action per combination, the first
column varying slowest; each action is labelled with its ranges, ``input_4hourly 2/5
(50-180), max_dose_vaso 0/5 (0)``. The raw doses are kept as corpus columns of the same names,
so the bins can be fitted again (``aoc split``).
"""

from __future__ import annotations

import itertools

import numpy as np

from aoc_cli.errors import AocError, param


def parse(text: str | dict | None) -> dict[str, int] | None:
    """``"input_4hourly=5,max_dose_vaso=5"`` (or a dict) -> {column: bins}."""
    if text is None or isinstance(text, dict):
        return None if text is None else {str(k): int(v) for k, v in text.items()}
    out: dict[str, int] = {}
    for part in [p.strip() for p in text.split(",") if p.strip()]:
        col, _, n = part.partition("=")
        try:
            bins = int(n)
        except ValueError:
            bins = 0
        if not col.strip() or bins < 2:
            raise AocError(f"{param('bin_actions', text)}: write COLUMN=BINS (BINS >= 2), "
                           f"comma-separated, e.g. input_4hourly=5,max_dose_vaso=5")
        out[col.strip()] = bins
    return out


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


def fit(doses: dict[str, np.ndarray], bins: dict[str, int], where) -> dict:
    """``{"columns": [...], "bins": [...], "edges": {col: [low, cut..., high]}}`` from the
    doses (N,) of each column: ``low``/``high`` the smallest and largest non-zero dose, the
    cuts their quantiles."""
    edges = {}
    for col, n in bins.items():
        nonzero = doses[col][doses[col] > 0]
        distinct = np.unique(nonzero)
        if len(distinct) < n - 1:
            raise AocError(f"{where}: {param('bin_actions', f'{col}={n}')} needs at least "
                           f"{n - 1} distinct non-zero doses of {col!r} for its {n - 1} "
                           f"non-zero bins, the data hold {len(distinct)}: use fewer bins")
        cuts = np.quantile(nonzero, np.arange(1, n - 1) / (n - 1)) if n > 2 else []
        edges[col] = [float(distinct[0]), *map(float, cuts), float(distinct[-1])]
    return {"columns": list(bins), "bins": [int(n) for n in bins.values()], "edges": edges}


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
        names += [f"{col} {j}/{n} ({_fmt(e[j - 1])}-{_fmt(e[j])})" for j in range(1, n)]
        per_col.append(names)
    return [", ".join(combo) for combo in itertools.product(*per_col)]


def check_like(spec: dict, bins: dict[str, int] | None, where, source: str) -> None:
    """``--bin-actions`` given with ``--bin-like`` or ``--append`` must agree with the edges."""
    if bins is not None and (list(bins) != spec["columns"] or
                             [int(b) for b in bins.values()] != spec["bins"]):
        raise AocError(f"{where}: {param('bin_actions')} differs from the bins of {source} "
                       f"({', '.join(f'{c}={n}' for c, n in zip(spec['columns'], spec['bins']))})"
                       ": drop it (the corpus's edges apply)")
