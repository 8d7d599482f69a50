"""`aoc explain ... --html FILE`: the decision page of explained decisions and the overview
page of an ``aoc evaluate --steps`` file, written: what goes on them (the audit episode's OOD
band, the index's typical residual) gathered here, the HTML built by :mod:`aoc_cli.report`
(:mod:`aoc_cli.report.pages`)."""

from __future__ import annotations

from pathlib import Path

from aoc_cli.errors import BadInput, call
from aoc_cli.explanation.decisions import audit_band
from aoc_cli.index import load_index
from aoc_cli.report.html import check_html_path, write_page
from aoc_cli.report.overview import action_names, audit_episode, steps_episodes
from aoc_cli.report.pages import decision_page, overview_page


def check_html(path: Path, store_root) -> None:
    """Refuse an --html path in the store, in a missing or unwritable folder, before any
    work."""
    check_html_path(path, store_root)


def write_html(path: Path, records: list[dict], corpus, session=None, audit=None,
               episode: int = 0, step: int = 0, source=None) -> None:
    """The decision page of ``records``; with an audit log (and its session), the overview
    of its episode first, each step linked to its section; ``source``: the corpus logged
    steps were read from (``--data``)."""
    episodes, typical = None, None
    if audit is not None and session is not None:
        ep = audit_episode(corpus, audit, episode, upper=None)
        ep.upper = audit_band(session, ep.residual)
        ep.actions = action_names(corpus)
        episodes = [ep]
        t = session.index.typical
        typical = {"p50": t.p50, "p90": t.p90, "p99": t.p99}
    write_page(path, decision_page(records, corpus, episodes, typical, detail=step,
                                       source=source))


def steps_overview(corpus, steps_file: Path, path: Path, model, index_id: str) -> None:
    """The overview page of an `aoc evaluate --steps` file, against the index's typical
    residual."""
    if not Path(steps_file).is_file():
        raise BadInput(steps_file, f"no such steps file: {steps_file} (write one with `"
                       f"{call('evaluate', corpus.name, data='HELD_OUT', steps_file='FILE')}`)",
                       param="steps_file")
    t = load_index(corpus, model, index_id).typical
    typical = {"p50": t.p50, "p90": t.p90, "p99": t.p99}
    episodes = steps_episodes(corpus, steps_file, typical)
    for ep in episodes:
        ep.actions = action_names(corpus)
    write_page(path, overview_page(corpus, episodes, typical, Path(steps_file).name))
