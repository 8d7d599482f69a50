"""Measured values on the decision page: the query's and the supporting rows' observations as
the corpus stores them, in its own units ("SpO2 92 against 95"), named by the observation
space, with the corpus's numeric columns beside them (icu-sepsis's discrete ``state``), and
every cell imputed at ingest marked (``Corpus.imputed_mask``).

The cards' charts draw standardised features (every feature on one axis); these tables are
what a clinician reads. Every user string is escaped.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from aoc_cli.report.html import esc

#: Features in the values table when the observation has more: the largest attributions.
MAX_VALUES = 16
#: Numeric corpus columns shown beside the features (a tabular task's state, a propensity).
MAX_COLUMNS = 4
#: The mark of an imputed cell; the page says what it means (:func:`legend`).
MARK = "&dagger;"
IMPUTED_TIP = "imputed: not measured at this step"
#: A cell this many of the corpus's standard deviations from the query's value is shaded.
FAR = (1.0, 2.0)


@dataclass
class Values:
    """One column of the values table: a title, a sub-title (the row's weight), the
    observation (d_o,), its imputed cells (d_o,) bool (None: none imputed, or not known), the
    numeric columns {name: value}."""

    title: str
    sub: str
    observation: np.ndarray
    imputed: np.ndarray | None
    columns: dict


def imputed_mask(corpus) -> np.ndarray | None:
    """(N, d_o) bool, true where a cell was imputed at ingest; None when none was (or the
    corpus was written before imputation existed)."""
    mask = getattr(corpus, "imputed_mask", None)
    if mask is None:
        return None
    mask = np.asarray(mask, bool)
    if mask.shape != (corpus.n_rows, corpus.observation_dim):
        raise ValueError(f"corpus {corpus.name!r}: imputed mask of shape {mask.shape}, "
                         f"expected ({corpus.n_rows}, {corpus.observation_dim})")
    return mask


def columns_of(corpus, rows: np.ndarray, names: list[str]) -> list[dict]:
    """{column: value} for each of ``rows`` (any order), for the ``names`` it has."""
    have = [c for c in names if c in (corpus.manifest.get("columns") or [])]
    cols = {c: np.asarray(corpus.read(f"columns/{c}", rows), np.float64) for c in have}
    return [{c: float(v[i]) for c, v in cols.items()} for i in range(len(rows))]


def history_rows(rows: np.ndarray, length: int) -> np.ndarray:
    """(R, L) the corpus rows of each row's L previous steps, oldest first (clipped at 0
    where the episode has fewer: those positions are masked by the history's ``mask``)."""
    return np.clip(np.asarray(rows, np.int64)[:, None] - length + np.arange(length), 0, None)


def shown_features(weights: np.ndarray) -> tuple[list[int], str]:
    """The features of the values table, in the observation's own order: all of them, or the
    MAX_VALUES of the largest ``weights`` (attributions); and a note saying which."""
    d_o = len(weights)
    if d_o <= MAX_VALUES:
        return list(range(d_o)), ""
    top = np.argsort(-np.asarray(weights), kind="stable")[:MAX_VALUES]
    return sorted(int(j) for j in top), (f"{MAX_VALUES} of {d_o} features: those that made "
                                         "the rows count most")


def measured(value: float) -> str:
    """A measured value as a chart reads: whole numbers whole (an age in days 24470, not
    2.447e+04), others to 4 significant digits without an exponent between 0.001 and 10^6."""
    v = float(value)
    if not math.isfinite(v):
        return str(v)
    if v == round(v) and abs(v) < 1e15:
        return str(int(round(v)))
    a = abs(v)
    if a >= 1e6 or a < 1e-3:
        return f"{v:.4g}"
    text = f"{v:.{max(0, 3 - math.floor(math.log10(a)))}f}"
    return text.rstrip("0").rstrip(".") if "." in text else text


def cell(value: float, imputed: bool, far: float | None = None, tag: str = "td") -> str:
    """One value: its number, the imputed mark, shaded when far from the query's."""
    cls = ["imputed"] if imputed else []
    if far is not None and far > FAR[1]:
        cls.append("far2")
    elif far is not None and far > FAR[0]:
        cls.append("far1")
    attrs = (f' class="{" ".join(cls)}"' if cls else "") + \
        (f' title="{IMPUTED_TIP}"' if imputed else "")
    return f"<{tag}{attrs}>{measured(value)}{MARK if imputed else ''}</{tag}>"


def values_table(features: list[int], names: list[str], std: np.ndarray, query: Values,
                 rows: list[Values], note: str = "") -> str:
    """The query's values beside each supporting row's: one line per feature, then the
    numeric columns; a row's cell is shaded by its distance from the query's value in the
    corpus's standard deviations."""
    head = "".join(f"<th>{esc(v.title)}<br><span class=\"muted\">{esc(v.sub)}</span></th>"
                   for v in [query, *rows])
    lines = []
    for j in features:
        q = float(query.observation[j])
        cells = [cell(q, _imp(query, j), tag="td")]
        cells += [cell(v.observation[j], _imp(v, j), abs(float(v.observation[j]) - q) / std[j])
                  for v in rows]
        lines.append(f"<tr><th>{esc(names[j])}</th>{''.join(cells)}</tr>")
    columns = sorted({c for v in [query, *rows] for c in v.columns})
    if columns:
        lines.append(f'<tr class="columns"><th colspan="{2 + len(rows)}">other columns of the '
                     "log (not read by the model)</th></tr>")
    for c in columns:
        cells = "".join(f"<td>{measured(v.columns[c])}</td>" if c in v.columns else "<td>-</td>"
                        for v in [query, *rows])
        lines.append(f'<tr class="column"><th>{esc(c)}</th>{cells}</tr>')
    note = f'<p class="muted">{esc(note)}</p>' if note else ""
    return (f'<div class="values-card"><h3>Measured values: this step and its past cases</h3>'
            f'{note}<div class="scroll"><table class="values"><tr><th>feature</th>{head}</tr>'
            f'{"".join(lines)}</table></div></div>')


def card_values(features: list[int], names: list[str], query: Values, row: Values) -> str:
    """A card's few values: each feature's value at the query against the row's (the
    columns of the log are in the values table)."""
    lines = "".join(
        f"<tr><td>{esc(names[j])}</td>{cell(query.observation[j], _imp(query, j))}"
        f"{cell(row.observation[j], _imp(row, j))}</tr>" for j in features)
    return (f'<table class="kv vals"><tr><th>feature</th><th>query</th><th>this row</th></tr>'
            f"{lines}</table>")


def legend(rule: str | None, any_imputed: bool, query_known: bool,
           units: str | None = None) -> str:
    """What the marks and shades of the values mean, in a line; ``units`` what the stored
    values are where a task says (icu-sepsis: normalised), else the corpus's own units."""
    parts = [f"Values as the corpus stores them ({esc(units or 'in its own units')}). Shaded: "
             "more than 1 (darker: 2) of the corpus's standard deviations from this step's "
             "value."]
    if any_imputed:
        how = f" (rule: {rule})" if rule else ""
        parts.append(f"{MARK} imputed: the cell was empty in the source and was filled at "
                     f"ingest{esc(how)}.")
        if not query_known:
            parts.append("Whether this step's own cells were measured is not known (it was "
                         "not read from a corpus).")
    return f'<p class="muted legend">{" ".join(parts)}</p>'


def _imp(v: Values, j: int) -> bool:
    return v.imputed is not None and bool(v.imputed[j])
