"""The cohort report's SVG charts (``aoc evaluate --html``): the forest plot of the policies'
values, the agreement heatmap, the residual's histogram. Hand-written like
:mod:`aoc_cli.report.svg` (no script, every label escaped); a withheld estimate is drawn as its
reason, never as a number."""

from __future__ import annotations

import math

from aoc_cli.report.html import esc, num

#: Pixels of a forest plot's row and columns.
ROW = 22
LABEL_W = 230
PLOT_W = 420
TEXT_W = 250
#: Labels longer than this are drawn as the actions' numbers (with a key) on the heatmap.
SHORT_LABEL = 16


def _scale(values: list[float], lo_pad: float = 0.06):
    lo, hi = min(values), max(values)
    if hi - lo < 1e-12:
        lo, hi = lo - 1.0, hi + 1.0
    pad = lo_pad * (hi - lo)
    return lo - pad, hi + pad


def _clip(text: str, n: int) -> str:
    return text if len(text) <= n else text[:n - 1] + "\u2026"


def forest_plot(rows: list[dict]) -> str:
    """One row per (policy, estimator): a point and its interval on a shared axis, its
    numbers on the right; a withheld row (``estimate`` None) is the word "withheld" and its
    reason across the plot, with no mark."""
    shown = [v for r in rows if r["estimate"] is not None
             for v in (r["estimate"], r.get("low"), r.get("high")) if v is not None]
    lo, hi = _scale(shown) if shown else (0.0, 1.0)
    top, width = 24, LABEL_W + PLOT_W + TEXT_W
    height = top + ROW * len(rows) + 26

    def x(v):
        return LABEL_W + (v - lo) / (hi - lo) * PLOT_W

    out = [f'<svg class="forest" xmlns="http://www.w3.org/2000/svg" width="{width}" '
           f'height="{height}" viewBox="0 0 {width} {height}" role="img" '
           'aria-label="forest plot of the policies\' values">',
           f'<text x="4" y="14" font-weight="600">policy / estimator</text>'
           f'<text x="{LABEL_W}" y="14">value (95% interval)</text>'
           f'<text x="{LABEL_W + PLOT_W + 8}" y="14">estimate [low, high]</text>']
    for t in _ticks(lo, hi):
        out.append(f'<line x1="{x(t):.1f}" y1="{top - 4}" x2="{x(t):.1f}" '
                   f'y2="{top + ROW * len(rows)}" stroke="#e3e6ec"/>'
                   f'<text x="{x(t):.1f}" y="{top + ROW * len(rows) + 14}" '
                   f'text-anchor="middle">{num(t, 3)}</text>')
    previous = None
    for i, r in enumerate(rows):
        y = top + ROW * i + ROW / 2
        policy = r["policy"] if r["policy"] != previous else ""
        previous = r["policy"]
        withheld = r["estimate"] is None
        out.append(f'<g class="forest-row" data-policy="{esc(r["policy"])}" '
                   f'data-estimator="{esc(r["estimator"])}" '
                   f'data-withheld="{"true" if withheld else "false"}">')
        if i and policy:
            out.append(f'<line x1="0" y1="{y - ROW / 2:.1f}" x2="{width}" '
                       f'y2="{y - ROW / 2:.1f}" stroke="#ccd3de"/>')
        out.append(f'<text x="4" y="{y + 3:.1f}" font-weight="600">{esc(_clip(policy, 22))}'
                   f'</text><text x="{LABEL_W - 6}" y="{y + 3:.1f}" text-anchor="end">'
                   f'{esc(r["estimator"])}</text>')
        if withheld:
            reason = str(r.get("reason") or "not estimable from this log")
            out.append(f'<text class="withheld" x="{LABEL_W + 4}" y="{y + 3:.1f}" '
                       f'fill="#8a4b00" font-style="italic"><title>{esc(reason)}</title>'
                       f'withheld: {esc(_clip(reason, 110))}</text>')
        else:
            colour = "#555" if r["policy"] == "logged behaviour" else "#0072B2"
            if r.get("low") is not None and r.get("high") is not None:
                out.append(f'<line x1="{x(r["low"]):.1f}" y1="{y:.1f}" x2="{x(r["high"]):.1f}" '
                           f'y2="{y:.1f}" stroke="{colour}" stroke-width="2"/>')
            out.append(f'<rect x="{x(r["estimate"]) - 4:.1f}" y="{y - 4:.1f}" width="8" '
                       f'height="8" fill="{colour}"><title>{esc(r["policy"])} '
                       f'{esc(r["estimator"])}: {num(r["estimate"])}</title></rect>')
            interval = "" if r.get("low") is None else \
                f' [{num(r["low"])}, {num(r["high"])}]'
            out.append(f'<text x="{LABEL_W + PLOT_W + 8}" y="{y + 3:.1f}">'
                       f'{num(r["estimate"])}{interval}</text>')
        out.append("</g>")
    out.append("</svg>")
    return "".join(out)


def _ticks(lo: float, hi: float, n: int = 5) -> list[float]:
    step = 10 ** math.floor(math.log10((hi - lo) / n))
    for m in (1, 2, 5, 10):
        if (hi - lo) / (step * m) <= n:
            step *= m
            break
    first = math.ceil(lo / step) * step
    return [first + i * step for i in range(int((hi - first) / step) + 1)]


def heatmap(rows: list[str], columns: list[str], counts: list[list[int]],
            numbers: list | None = None, row_title: str = "logged",
            column_title: str = "decided") -> str:
    """Counts (R, C) as shaded cells, each row's shade its share of the row (what the policy
    decides where this was logged); the diagonal outlined. Labels longer than
    :data:`SHORT_LABEL` are drawn as ``numbers`` (the full label is each cell's tooltip)."""
    short = all(len(t) <= SHORT_LABEL for t in rows + columns) or numbers is None
    rlab = rows if short else [str(a) for a in numbers]
    clab = columns if short else [str(a) for a in numbers]
    cell = 30 if len(columns) <= 12 else 20
    left = 14 + int(6 * max(len(t) for t in rlab))
    top = 24 + int(6 * max(len(t) for t in clab)) if short else 36
    width, height = left + cell * len(columns) + 10, top + cell * len(rows) + 20
    out = [f'<svg class="heatmap" xmlns="http://www.w3.org/2000/svg" width="{width}" '
           f'height="{height}" viewBox="0 0 {width} {height}" role="img" '
           f'aria-label="{esc(row_title)} against {esc(column_title)}">',
           f'<text x="{left}" y="11">{esc(column_title)} &#8594;</text>'
           f'<text x="4" y="{top - 4}">{esc(row_title)} &#8595;</text>']
    for j, t in enumerate(clab):
        cx = left + cell * j + cell / 2
        out.append(f'<text transform="translate({cx + 3:.1f},{top - 4}) rotate(-60)">'
                   f'{esc(t)}</text>' if short else
                   f'<text x="{cx:.1f}" y="{top - 4}" text-anchor="middle">{esc(t)}</text>')
    for i, t in enumerate(rlab):
        total = max(1, sum(counts[i]))
        y = top + cell * i
        out.append(f'<text x="{left - 4}" y="{y + cell / 2 + 3:.1f}" text-anchor="end">'
                   f'{esc(t)}</text>')
        for j, c in enumerate(counts[i]):
            share = c / total
            shade = f"rgba(0,114,178,{0.08 + 0.92 * share:.3f})" if c else "#fff"
            stroke = ' stroke="#333" stroke-width="1.5"' if i == j else ' stroke="#e3e6ec"'
            tip = f"{row_title} {rows[i]}, {column_title} {columns[j]}: {c} steps ({share:.0%})"
            out.append(f'<rect class="cell" data-count="{c}" x="{left + cell * j}" y="{y}" '
                       f'width="{cell}" height="{cell}" fill="{shade}"{stroke}>'
                       f'<title>{esc(tip)}</title></rect>')
            if c and cell >= 30:
                fill = "#fff" if share > 0.55 else "#1d2330"
                out.append(f'<text x="{left + cell * j + cell / 2:.1f}" '
                           f'y="{y + cell / 2 + 3:.1f}" text-anchor="middle" '
                           f'style="fill:{fill}">{c}</text>')
    out.append("</svg>")
    return "".join(out)


def histogram(edges: list[float], counts: list[int], marks: dict, width: int = 640,
              height: int = 170, xlabel: str = "") -> str:
    """Bars of ``counts`` (B,) over ``edges`` (B + 1,), with a dashed line at each of
    ``marks`` {label: x}."""
    left, right, top, bottom = 40, 10, 10, 30
    w, h = width - left - right, height - top - bottom
    lo, hi = edges[0], edges[-1]
    peak = max(max(counts), 1)

    def px(v):
        return left + (v - lo) / ((hi - lo) or 1.0) * w

    out = [f'<svg class="histogram" xmlns="http://www.w3.org/2000/svg" width="{width}" '
           f'height="{height}" viewBox="0 0 {width} {height}" role="img" '
           f'aria-label="{esc(xlabel)}">',
           f'<rect x="{left}" y="{top}" width="{w}" height="{h}" fill="none" stroke="#bbb"/>',
           f'<text x="{left - 3}" y="{top + 8}" text-anchor="end">{peak}</text>'
           f'<text x="{left - 3}" y="{top + h}" text-anchor="end">0</text>']
    for i, c in enumerate(counts):
        bh = c / peak * h
        out.append(f'<rect class="bar" x="{px(edges[i]) + 0.5:.1f}" y="{top + h - bh:.1f}" '
                   f'width="{max(px(edges[i + 1]) - px(edges[i]) - 1, 0.5):.1f}" '
                   f'height="{bh:.1f}" fill="#0072B2"><title>{num(edges[i], 3)} to '
                   f'{num(edges[i + 1], 3)}: {c} steps</title></rect>')
    for k, (label, v) in enumerate(marks.items()):
        if v is None or not lo <= v <= hi:
            continue
        out.append(f'<line x1="{px(v):.1f}" y1="{top}" x2="{px(v):.1f}" y2="{top + h}" '
                   f'stroke="#D55E00" stroke-dasharray="4 3"/><text x="{px(v) + 3:.1f}" '
                   f'y="{top + 10 + 11 * k}" style="fill:#D55E00">{esc(label)}</text>')
    out.append(f'<text x="{left}" y="{top + h + 12}">{num(lo, 3)}</text>'
               f'<text x="{left + w}" y="{top + h + 12}" text-anchor="end">{num(hi, 3)}</text>'
               f'<text x="{left + w / 2:.1f}" y="{top + h + 24}" text-anchor="middle">'
               f'{esc(xlabel)}</text></svg>')
    return "".join(out)
