"""``aoc evaluate --html FILE``: the cohort report written, with the decision page of each step
it lists (``--pages DIR``, beside the report by default), each page the one ``aoc explain
--data HELD_OUT --episode E --step T --html`` writes. The data are
:func:`aoc_cli.evaluation.cohort.cohort`'s, the HTML :mod:`aoc_cli.report.cohort`'s."""

from __future__ import annotations

import os
from pathlib import Path

from aoc_cli.errors import BadInput, param
from aoc_cli.evaluation.cohort import TOP, cohort
from aoc_cli.explanation.decisions import explain_logged_step
from aoc_cli.explanation.pages import write_html
from aoc_cli.report.cohort import cohort_page
from aoc_cli.report.html import check_html_path, write_page
from aoc_cli.store.paths import check_output


def pages_folder(html: Path, pages: Path | None) -> Path:
    """Where the listed steps' decision pages go: ``pages``, else ``<report>-pages`` beside
    the report."""
    return Path(pages) if pages is not None else html.with_name(html.stem + "-pages")


def check_report(html, pages, store_root) -> None:
    """Refuse a report path or a pages folder in the store, or unwritable, before any
    work."""
    html = check_html_path(Path(html), store_root)
    folder = pages_folder(Path(html), None if pages is None else Path(pages))
    check_output(folder, "pages", store_root, folder=True)


def cohort_data(session, data, summary: dict, res, by: str | None = None,
                top: int = TOP) -> dict:
    """The report's data of an evaluation by ``session`` of held-out corpus ``data``."""
    t = session.index.typical
    return cohort(summary, res, session.corpus, data, {"p50": t.p50, "p90": t.p90,
                                                       "p99": t.p99}, by=by, top=top)


def write_cohort_report(session, data, summary: dict, res, html, pages=None,
                        by: str | None = None, top: int = TOP) -> dict:
    """Write the report to ``html`` and the decision page of each listed step into the
    pages folder (:func:`pages_folder`); returns the report's data, each listed step's
    ``page`` its path relative to the report."""
    html = Path(html)
    c = cohort_data(session, data, summary, res, by, top)
    folder = pages_folder(html, None if pages is None else Path(pages))
    if c["top"]["steps"]:
        try:
            folder.mkdir(parents=True, exist_ok=True)
        except OSError as err:
            raise BadInput(folder, f"{param('pages')} {folder}: cannot create it "
                           f"({err.strerror or err})", param="pages") from None
    for s in c["top"]["steps"]:
        path = folder / f"episode-{s['episode']}-step-{s['step']}.html"
        records = explain_logged_step(session, data, s["episode"], s["step"])
        write_html(path, records, session.corpus, source=data)
        s["page"] = Path(os.path.relpath(path.resolve(), html.resolve().parent)).as_posix()
    write_page(html, cohort_page(c))
    return c
