"""Decision pages benchmark (issue 25): the seconds to write ``aoc explain --html`` pages.

    .venv/bin/python benchmarks/perf/pages.py [--store DIR] [--repeats 5] [--screenshot FILE]

Goals: a decision page in under 1 s once the session is open; the overview page of a
1,000-step audit log in under 10 s. Builds (once, in ``--store``) the README's ward walkthrough
(500 patients, ``aoc collect ward``, an imitation model trained by ``aoc train --mode
imitation``, its index) and a maze corpus with a value model (120 episodes). Times, in this
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

import argparse
import statistics
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))


def build(store_root: Path):
    from aoc_cli.belief import BeliefConfig, train_model
    from aoc_cli.envs import collect
    from aoc_cli.corpus_index import build_index
    from aoc_cli.store import Store

    store = Store(store_root)
    if "ward" not in store.names():
        data, _ = collect("ward", episodes=500, seed=0)
        corpus = store.write("ward", data)
        train_model(corpus, BeliefConfig(mode="imitation", seed=0, threads=1), "default")
        build_index(corpus)
    if "maze" not in store.names():
        data, _ = collect("maze", episodes=120, seed=0)
        corpus = store.write("maze", data)
        train_model(corpus, BeliefConfig(seed=0, threads=1, max_epochs=6, patience=3),
                    "default")
        build_index(corpus)
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
        h = type(hist)(*(np.asarray(x)[i:i + 1] for x in hist))
        decisions.append(session.controller.decide(corpus.observations[r], h))
        histories.append(tuple(h))
    residuals = np.array([d.residual for d in decisions])
    ep = SimpleNamespace(episode=0, seed=0, total_return=0.0, length=steps, success=None,
                         decisions=decisions, observations=list(corpus.observations[rows]),
                         rewards=np.zeros(steps), ood=list(residuals > np.quantile(
                             residuals, 0.98)), histories=histories)
    write_audit(path, [ep], session.meta(), corpus=corpus)


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--store", type=Path, default=None)
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--screenshot", type=Path, default=None)
    args = ap.parse_args()
    from aoc_cli.report.explain_pages import write_html
    from aoc_cli.control import explain_logged_step, read_audit_step, replay_decision
    from aoc_cli.control.explain import explain_decisions
    from aoc_cli.control import open_session

    root = args.store or Path(tempfile.mkdtemp(prefix="aoc-pages-")) / "store"
    store = build(root)
    out = Path(tempfile.mkdtemp(prefix="aoc-pages-out-"))
    ward = store.corpus("ward")
    session = open_session(ward)
    times = []
    for i in range(args.repeats):
        start = time.perf_counter()
        records = explain_logged_step(session, ward, 7 + i, 3)
        write_html(out / "ward.html", records, ward)
        times.append(time.perf_counter() - start)
    print(f"decision page (ward, {len(records[0]['support'])} supporting rows): median "
          f"{statistics.median(times):.3f} s; runs {', '.join(f'{t:.3f}' for t in times)}")
    maze = store.corpus("maze")
    msession = open_session(maze)
    log = out / "audit.h5"
    audit_log(msession, log)
    times = []
    for _ in range(max(3, args.repeats // 2)):
        start = time.perf_counter()
        recorded = read_audit_step(log, 0, 500)
        rec = explain_decisions(msession, recorded["observation"], recorded["history"],
                                [replay_decision(msession, recorded)], step=500)
        write_html(out / "audit.html", rec, maze, session=msession, audit=log, episode=0,
                   step=500)
        times.append(time.perf_counter() - start)
    print(f"overview page (1,000-step audit log, maze): median {statistics.median(times):.3f} "
          f"s; runs {', '.join(f'{t:.3f}' for t in times)}; "
          f"{(out / 'audit.html').stat().st_size / 1e6:.2f} MB")
    if args.screenshot is not None:
        from tests.report.chromium import Browser

        b = Browser()
        try:
            b.open(out / "ward.html")
            b.screenshot(args.screenshot, width=1100)
        finally:
            b.close()
        print(f"wrote {args.screenshot}")


if __name__ == "__main__":
    main()
