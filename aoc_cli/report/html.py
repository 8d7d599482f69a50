"""Self-contained HTML pages: the shell (inline styles, no script, no network), escaping, and
an atomic write.

Everything that comes from a user's files (patient ids, tag values, action labels, feature
names) goes through :func:`esc` (``html.escape`` with quotes) before it reaches the page, and
the pages carry no script at all, so nothing from a log can run in them: a tag value
``<script>alert(1)</script>`` is shown as that text.
"""

from __future__ import annotations

import html
import os
import re
import tempfile
from pathlib import Path

from aoc_cli.errors import BadInput, param
from aoc_cli.store import atomic_path
from aoc_cli.store.paths import check_output

STYLE = """
body{font:14px/1.45 system-ui,-apple-system,"Segoe UI",Roboto,sans-serif;color:#1d2330;
 margin:24px auto;max-width:1100px;padding:0 16px}
h1{font-size:22px;margin:0 0 4px}h2{font-size:18px;margin:28px 0 8px;border-bottom:1px solid #ccd}
h3{font-size:15px;margin:14px 0 6px}
.lede{font-size:16px;background:#f3f6fb;border-left:4px solid #3b6fb6;padding:10px 14px}
.warn{color:#8a4b00}.muted{color:#5b6472}.ok{color:#1d6b36}.bad{color:#a4262c}
table{border-collapse:collapse;margin:6px 0}td,th{border:1px solid #d6dae2;padding:3px 8px;
 text-align:left;font-variant-numeric:tabular-nums}th{background:#f3f5f8}
.cards{display:grid;grid-template-columns:repeat(auto-fill,minmax(330px,1fr));gap:12px}
.card{border:1px solid #ccd3de;border-radius:6px;padding:10px 12px;break-inside:avoid}
.card h3{margin:0 0 4px}.kv{font-size:13px}.kv b{font-weight:600}
.bar{display:inline-block;height:9px;vertical-align:middle}
.pos{background:#3b6fb6}.neg{background:#c0504d}
svg text{font:10px system-ui,sans-serif;fill:#333}
.step{border-top:1px solid #e3e6ec;padding:4px 0}.step.flag{background:#fff4e5}
.values-card{border:1px solid #ccd3de;border-radius:6px;padding:8px 12px;margin:8px 0}
.values-card h3{margin:0 0 4px}.scroll{overflow-x:auto}
table.values td,table.values th{font-size:12.5px;padding:2px 6px}
table.values td{text-align:right}tr.columns th{font-weight:400;color:#5b6472;
 background:#fff;border-top:2px solid #ccd3de}
.vals td{text-align:right}.vals td:first-child{text-align:left}
.bars td:last-child{white-space:nowrap}
td.far1{background:#fdf1dc}td.far2{background:#f8d9a8}
td.imputed{font-style:italic;color:#6b4c9a;text-decoration:underline dotted}
.legend{font-size:12.5px;margin:2px 0 10px}
a{color:#2a5aa0}
@media print{body{margin:0;max-width:none}.cards{grid-template-columns:1fr 1fr}
 .scroll{overflow:visible}table.values{width:100%;table-layout:fixed}
 table.values td,table.values th{font-size:8px;padding:1px 2px;overflow-wrap:anywhere}
 a{color:inherit;text-decoration:none}.lede{border-left-color:#000}}
"""


def esc(value) -> str:
    """Text for the page: any value as a string, with &, <, >, " and ' escaped."""
    return html.escape("" if value is None else str(value), quote=True)


def num(x, digits: int = 4) -> str:
    """A number as a person reads it (``-`` for none)."""
    if x is None:
        return "-"
    if isinstance(x, (list, tuple)):
        return "[" + ", ".join(num(v, digits) for v in x) + "]"
    if isinstance(x, bool):
        return str(x)
    if isinstance(x, int):
        return str(x)
    return f"{float(x):.{digits}g}"


def page(title: str, body: str) -> str:
    """A whole HTML document: ``title`` (plain text, escaped here) and ``body`` (HTML built
    with :func:`esc`)."""
    return ("<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\">"
            "<meta http-equiv=\"Content-Security-Policy\" content=\"default-src 'none'; "
            "style-src 'unsafe-inline'; img-src data:\">"
            f"<title>{esc(title)}</title><style>{STYLE}</style></head><body>\n"
            f"{body}\n</body></html>\n")


def scoped_style(scope: str = ".aoc-page") -> str:
    """:data:`STYLE` with every rule under ``scope`` (``body`` becomes the scope itself): a
    page's look inside a notebook's cell without restyling the notebook."""
    def rule(match):
        selectors = ",".join(scope if s.strip() == "body" else f"{scope} {s.strip()}"
                             for s in match.group(1).split(","))
        return f"{selectors}{{{match.group(2)}}}"
    return re.sub(r"([^{}@]+)\{([^{}]*)\}", rule, STYLE)


def fragment(body: str) -> str:
    """``body`` (a page's HTML) as a notebook cell shows it: in a ``div.aoc-page`` with the
    pages' style scoped to it (:func:`scoped_style`); no script, as on the pages."""
    return f'<div class="aoc-page"><style>{scoped_style()}</style>{body}</div>'


def check_html_path(path, store_root) -> Path:
    """``html`` (a page's path): outside the store, in a folder that exists and can be written."""
    path = check_output(path, "html", store_root)
    parent = Path(path).resolve().parent
    try:  # a probe: access() says yes to root where the file system says no (/proc, ro mounts)
        if not os.access(parent, os.W_OK):
            raise PermissionError("permission denied")
        with tempfile.TemporaryFile(dir=parent):
            pass
    except OSError as err:
        raise BadInput(path, f"{param('html')} {path}: the folder {parent} is not writable "
                       f"({getattr(err, 'strerror', None) or err}); give another path") from None
    return path


def write_page(path, text: str) -> None:
    """Write a page atomically; a folder that cannot be written is an AocError."""
    try:
        with atomic_path(path, suffix=".html") as tmp:
            Path(tmp).write_text(text, encoding="utf-8")
    except OSError as err:
        raise BadInput(path, f"{param('html')} {path}: cannot write it "
                       f"({err.strerror or err})") from None
