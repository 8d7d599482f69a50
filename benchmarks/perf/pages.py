"""Decision pages benchmark (issue 25): the seconds to write ``aoc explain --html`` pages.

    .venv/bin/python benchmarks/perf/pages.py [--store DIR] [--repeats 5] [--screenshot FILE]
                                         [-f json]

Goals: a decision page in under 1 s once the session is open; the overview page of a
1,000-step audit log in under 10 s. Builds (once, in ``--store``, through the API) the README's
ward walkthrough (500 patients, ``aoc_cli.collect``, an imitation model trained with the paper's
settings, ``aoc_cli.train(mode="imitation", paper=True)``, its index) and a maze corpus with a
value model (120 episodes). Times, in this
process, with the session open:

* ``decision page (ward)``: ``explain_logged_step`` of a held-in step (decision, contrast,
  attributions of every supporting row) plus the page's HTML, written to a file;
* ``overview page, 1,000-step audit log (maze)``: an audit log of one 1,000-step episode (the
  controller's decisions at 1,000 logged states, written by ``write_audit``); the page of
  ``aoc explain --audit --html``: the episode read back, its OOD band replayed, one section per
  step with its supporting rows, and the detailed decision of one step.

Medians of ``--repeats`` runs, every run listed. ``--screenshot``: a PNG of the ward page in
headless Chromium (docs/decision-page.png).
"""

from __future__ import annotations

import sys
import tempfile
from pathlib import Path

import _harness as h
import numpy as np

import aoc_cli
from aoc_cli.control import read_audit_step
from aoc_cli.explanation import explain_logged_step, replay_decision
from aoc_cli.explanation.decisions import explain_decisions
from aoc_cli.explanation.pages import write_html
from aoc_cli.store import Store


def build(store_root: Path) -> Store:
    """The ward walkthrough's corpus, model and index and the maze corpus's, through the API
    (each made once; the paper's training settings, one torch thread)."""
    store = Store.open(store_root)
    h.corpus_ready(store, "ward", "ward", episodes=500, seed=0,
                   train=dict(paper=True, mode="imitation", seed=0, threads=1), index={})
    h.corpus_ready(store, "maze", "maze", episodes=120, seed=0,
                   train=dict(paper=True, seed=0, threads=1, max_epochs=6, patience=3),
                   index={})
    return store


def audit_log(session, path: Path, steps: int = 1000) -> None:
    """One episode of ``steps`` decisions at logged states of the corpus."""
    from types import SimpleNamespace

    from aoc_cli.control import write_audit

    corpus = session.corpus
    rows = np.arange(steps) % corpus.n_rows
    hist = corpus.history(rows, session.history_length)
    decisions, histories = [], []
    for i, r in enumerate(rows):
        one = type(hist)(*(np.asarray(x)[i:i + 1] for x in hist))
        decisions.append(session.controller.decide(corpus.observations[r], one))
        histories.append(tuple(one))
    residuals = np.array([d.residual for d in decisions])
    ep = SimpleNamespace(episode=0, seed=0, total_return=0.0, length=steps, success=None,
                         decisions=decisions, observations=list(corpus.observations[rows]),
                         rewards=np.zeros(steps), ood=list(residuals > np.quantile(
                             residuals, 0.98)), histories=histories)
    write_audit(path, [ep], session.meta(), corpus=corpus)


def main() -> None:
    ap = h.parser(__doc__, repeats=5)
    ap.add_argument("--store", type=Path, default=None)
    ap.add_argument("--screenshot", type=Path, default=None)
    args = ap.parse_args()
    root = args.store or Path(tempfile.mkdtemp(prefix="aoc-pages-")) / "store"
    store = build(root)
    out = Path(tempfile.mkdtemp(prefix="aoc-pages-out-"))
    ward = store.corpus("ward")
    session = aoc_cli.open_session("ward", store=store)

    def decision_page(i: int) -> int:
        records = explain_logged_step(session, ward, 7 + i, 3)
        write_html(out / "ward.html", records, ward, source=ward)
        return len(records[0]["support"])

    runs = h.repeat(decision_page, args.repeats)
    rows = [h.row("decision page (ward)", 1, runs, unit="pages", supporting_rows=runs.out)]
    maze = store.corpus("maze")
    msession = aoc_cli.open_session("maze", store=store)
    log = out / "audit.h5"
    audit_log(msession, log)

    def overview_page(_i: int) -> None:
        recorded = read_audit_step(log, 0, 500)
        rec = explain_decisions(msession, recorded["observation"], recorded["history"],
                                [replay_decision(msession, recorded)], step=500)
        write_html(out / "audit.html", rec, maze, session=msession, audit=log, episode=0,
                   step=500)

    runs = h.repeat(overview_page, max(3, args.repeats // 2))
    rows.append(h.row("overview page (1,000-step audit log, maze)", 1, runs, unit="pages",
                      page_mb=(out / "audit.html").stat().st_size / 1e6))
    h.emit(rows, args.format)
    if args.screenshot is not None:  # the repository on PYTHONPATH: tests/ is not installed
        from tests.report.chromium import Browser

        b = Browser()
        try:
            b.open(out / "ward.html")
            b.screenshot(args.screenshot, width=1100)
        finally:
            b.close()
        print(f"wrote {args.screenshot}", file=sys.stderr)


if __name__ == "__main__":
    main()
