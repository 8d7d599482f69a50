"""Small inline SVG charts for the HTML pages.

Hand-written rather than matplotlib: a decision page draws one chart per supporting row (up
to d_b + 1 = 21) and an overview page links every step's marker to its section; matplotlib
renders a small figure to SVG slowly for a page of cards (docs/notes/benchmarks-rounds.md, "Figures once
in docstrings") and cannot put a link on a marker. These are polylines and circles with escaped labels, a few hundred bytes each,
crisp when printed.
"""

from __future__ import annotations

import numpy as np

from aoc_cli.report.html import esc

#: Colours of the series (colour-blind safe: Okabe-Ito).
PALETTE = ["#0072B2", "#E69F00", "#009E73", "#CC79A7", "#56B4E9", "#D55E00", "#F0E442",
           "#000000"]


def _fmt(v: float) -> str:
    return f"{v:.3g}"


def chart(x, series: list[dict], width: int = 320, height: int = 130, title: str = "",
          band: tuple | None = None, points: list[dict] | None = None,
          ylabel: str = "", legend: bool = True, yticks: list[tuple] | None = None,
          left: int = 40) -> str:
    """An SVG line chart. ``x`` (T,); ``series``: dicts with ``y`` (T,) (NaN: a gap),
    ``colour``, optional ``dash`` (bool), ``label``; ``band`` (lower (T,), upper (T,), label)
    shaded; ``points``: dicts with ``x``, ``y``, ``colour``, optional ``href`` (a link, e.g.
    ``#step-12``), ``label`` (its tooltip) and ``shape`` ("x", "o", or "ring": hollow, an
    imputed value); ``yticks``: (y, label) pairs written on the y axis, each with a faint line
    (a discrete action's label at its row), instead of the range's two numbers; ``left`` the
    margin before the plot (at least the longest tick label's), to align charts stacked."""
    x = np.asarray(x, np.float64)
    ys = [np.asarray(s["y"], np.float64) for s in series]
    allv = [v[np.isfinite(v)] for v in ys]
    if band is not None:
        allv += [np.asarray(b, np.float64)[np.isfinite(np.asarray(b, np.float64))]
                 for b in band[:2]]
    allv += [np.asarray([p["y"] for p in points or []], np.float64)]
    flat = np.concatenate([a for a in allv if a.size] or [np.zeros(1)])
    lo, hi = float(flat.min()), float(flat.max())
    if hi - lo < 1e-12:
        lo, hi = lo - 1.0, hi + 1.0
    pad = 0.06 * (hi - lo)
    lo, hi = lo - pad, hi + pad
    x0, x1 = (float(x.min()), float(x.max())) if len(x) else (0.0, 1.0)
    if x1 - x0 < 1e-12:
        x0, x1 = x0 - 1, x1 + 1
    right, top = 8, 16 if title else 6
    left = max(left, tick_margin(yticks))
    bottom = 18 + (12 * ((len(series) + 2) // 3) if legend and any(
        s.get("label") for s in series) else 0)
    w, h = width - left - right, height - top - bottom

    def px(v):
        return left + (np.asarray(v, np.float64) - x0) / (x1 - x0) * w

    def py(v):
        return top + (hi - np.asarray(v, np.float64)) / (hi - lo) * h

    out = [f'<svg xmlns="http://www.w3.org/2000/svg" width="{width}" height="{height}" '
           f'viewBox="0 0 {width} {height}" role="img" aria-label="{esc(title or ylabel)}">']
    if title:
        out.append(f'<text x="{left}" y="11">{esc(title)}</text>')
    out.append(f'<rect x="{left}" y="{top}" width="{w}" height="{h}" fill="none" '
               'stroke="#bbb"/>')
    if yticks:
        for v, t in yticks:
            y = float(py(v))
            out.append(f'<line x1="{left}" y1="{y:.1f}" x2="{left + w}" y2="{y:.1f}" '
                       f'stroke="#e3e6ec"/><text x="{left - 3}" y="{y + 3:.1f}" '
                       f'text-anchor="end">{esc(t)}</text>')
    else:
        out.append(f'<text x="{left - 3}" y="{top + 8}" text-anchor="end">{_fmt(hi - pad)}'
                   '</text>')
        out.append(f'<text x="{left - 3}" y="{top + h}" text-anchor="end">{_fmt(lo + pad)}'
                   '</text>')
    out.append(f'<text x="{left}" y="{top + h + 11}">{_fmt(x0)}</text>')
    out.append(f'<text x="{left + w}" y="{top + h + 11}" text-anchor="end">{_fmt(x1)}</text>')
    if ylabel:
        out.append(f'<text x="{left + w / 2:.1f}" y="{top + h + 11}" text-anchor="middle">'
                   f'{esc(ylabel)}</text>')
    if band is not None:
        lower, upper = (np.asarray(b, np.float64) for b in band[:2])
        ok = np.isfinite(lower) & np.isfinite(upper)
        if ok.any():
            xs = px(x[ok])
            pts = [f"{a:.1f},{b:.1f}" for a, b in zip(xs, py(upper[ok]))] + \
                  [f"{a:.1f},{b:.1f}" for a, b in zip(xs[::-1], py(lower[ok])[::-1])]
            out.append(f'<polygon points="{" ".join(pts)}" fill="#999" fill-opacity="0.18" '
                       'stroke="none"/>')
    for s, y in zip(series, ys):
        dash = ' stroke-dasharray="4 3"' if s.get("dash") else ""
        for seg in _segments(np.isfinite(y)):
            pts = " ".join(f"{a:.1f},{b:.1f}" for a, b in zip(px(x[seg]), py(y[seg])))
            if len(seg) == 1:
                out.append(f'<circle cx="{px(x[seg])[0]:.1f}" cy="{py(y[seg])[0]:.1f}" r="2" '
                           f'fill="{s["colour"]}"/>')
            else:
                out.append(f'<polyline points="{pts}" fill="none" stroke="{s["colour"]}" '
                           f'stroke-width="1.5"{dash}/>')
    for p in points or []:
        cx, cy = float(px(p["x"])), float(py(p["y"]))
        if p.get("shape") == "x":
            mark = (f'<path d="M{cx - 3:.1f},{cy - 3:.1f}L{cx + 3:.1f},{cy + 3:.1f}M'
                    f'{cx - 3:.1f},{cy + 3:.1f}L{cx + 3:.1f},{cy - 3:.1f}" '
                    f'stroke="{p["colour"]}" stroke-width="1.6"/>')
        elif p.get("shape") == "ring":  # hollow: an imputed value
            mark = (f'<circle class="imputed" cx="{cx:.1f}" cy="{cy:.1f}" r="3.4" fill="#fff" '
                    f'stroke="{p["colour"]}" stroke-width="1.4"/>')
        else:
            mark = f'<circle cx="{cx:.1f}" cy="{cy:.1f}" r="2.6" fill="{p["colour"]}"/>'
        tip = f'<title>{esc(p.get("label", ""))}</title>' if p.get("label") else ""
        out.append(f'<a href="{esc(p["href"])}">{tip}{mark}</a>' if p.get("href")
                   else f"<g>{tip}{mark}</g>")
    if legend:
        labelled = [s for s in series if s.get("label")]
        for i, s in enumerate(labelled):
            lx = left + (i % 3) * (w / 3)
            ly = top + h + 24 + 12 * (i // 3)
            dash = ' stroke-dasharray="4 3"' if s.get("dash") else ""
            out.append(f'<line x1="{lx:.1f}" y1="{ly - 3}" x2="{lx + 14:.1f}" y2="{ly - 3}" '
                       f'stroke="{s["colour"]}" stroke-width="1.5"{dash}/>'
                       f'<text x="{lx + 17:.1f}" y="{ly}">{esc(s["label"])}</text>')
    out.append("</svg>")
    return "".join(out)


def tick_margin(yticks: list[tuple] | None) -> int:
    """The left margin the longest of ``yticks``' labels needs (about 5.5 px a character at
    10 px), 40 at least."""
    return max([40] + [int(8 + 5.5 * len(str(t))) for _, t in yticks or []])


def _segments(ok: np.ndarray) -> list[np.ndarray]:
    """Runs of consecutive True positions of ``ok`` (T,)."""
    idx = np.flatnonzero(ok)
    if not len(idx):
        return []
    return np.split(idx, np.flatnonzero(np.diff(idx) > 1) + 1)
