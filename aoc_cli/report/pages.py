"""Whole pages: a decision page (one or more decision sections) and an overview page (an
audit log's episode with its decision, or an ``aoc evaluate --steps`` file)."""

from __future__ import annotations

from aoc_cli.report.decision_page import PageContext, decision_section
from aoc_cli.report.html import esc, page
from aoc_cli.report.overview import Episode, episode_section


def _header(corpus, what: str) -> str:
    return (f"<h1>{esc(what)}</h1><p class=\"muted\">corpus {esc(corpus.name)} &middot; "
            f"{corpus.n_rows} rows, {corpus.n_episodes} episodes &middot; written by "
            "aoc explain --html</p>")


def decision_page(records: list[dict], corpus, episodes: list[Episode] | None = None,
                  typical: dict | None = None, detail: int | None = None,
                  source=None) -> str:
    """The HTML of a decision page: ``episodes`` (an overview) first when given, then one
    section per record (the first is ``#decision``); ``source`` the corpus logged steps were
    read from (``--data``: the query's imputed cells and columns)."""
    ctx = PageContext(corpus, source)
    parts = [_header(corpus, "Decision" if not episodes else "Decisions of an audit log")]
    for ep in episodes or []:
        parts.append(episode_section(ep, typical or {}, detail))
    for i, rec in enumerate(records):
        parts.append(decision_section(rec, ctx, "decision" if i == 0 else f"decision-{i}"))
    return page(f"aoc: {corpus.name}", "".join(parts))


def overview_page(corpus, episodes: list[Episode], typical: dict, source: str) -> str:
    """The HTML of an overview page of an ``aoc evaluate --steps`` file."""
    parts = [_header(corpus, f"Decisions of {source}")]
    parts.append("<p>" + " &middot; ".join(
        f'<a href="#episode-{esc(ep.key)}">{esc(ep.title)}</a>' for ep in episodes) + "</p>")
    parts += [episode_section(ep, typical) for ep in episodes]
    return page(f"aoc: {corpus.name}: {source}", "".join(parts))
