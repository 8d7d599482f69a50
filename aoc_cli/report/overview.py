"""The overview page of many decisions: an episode of an audit log (``aoc rollout --audit``)
or the steps of ``aoc evaluate --steps``. Per episode: the residual over time with the OOD
band and the flagged steps, the decisions over time, and one short section per step (its
decision, residual and supporting rows), each marker of the charts linked to its section.

Input is plain arrays and dicts (:class:`Episode`), read by :func:`audit_episodes` /
:func:`steps_episodes`; every user string is escaped; the page has no script.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field

import numpy as np

from aoc_cli.control.audit import read_audit_episode
from aoc_cli.errors import AocError, BadInput, call
from aoc_cli.report.html import esc, num
from aoc_cli.report.svg import chart, tick_margin


@dataclass
class Episode:
    """T decisions of one episode. ``residual`` (T,), ``upper`` (T,) the OOD band's upper edge
    (inf or NaN where none), ``flagged`` (T,) bool, ``decision`` (T,) the decided action (the
    first coordinate of a continuous one), ``logged`` (T,) or None, ``value`` (T,) or None,
    ``support`` T lists of (who, tags, weight), ``labels`` T action labels; ``actions``
    {action: label} of a discrete corpus (the decisions chart then draws one labelled row per
    action taken)."""

    title: str
    key: str
    residual: np.ndarray
    upper: np.ndarray
    flagged: np.ndarray
    decision: np.ndarray
    labels: list[str]
    support: list[list[tuple[str, str, float]]]
    logged: np.ndarray | None = None
    value: np.ndarray | None = None
    steps: np.ndarray | None = None
    notes: list[str] = field(default_factory=list)
    actions: dict[int, str] | None = None


def _who(corpus, rows: np.ndarray) -> tuple[list[str], list[str]]:
    """(episode id or number, "tag=value, ...") of corpus ``rows`` (any order)."""
    if not len(rows):
        return [], []
    order = np.argsort(rows)
    eps = corpus.episode_of(rows)
    ids = getattr(corpus, "episode_ids", None)
    who = [str(ids[e]) if ids is not None else f"episode {e}" for e in eps]
    tags_sorted = corpus.tag_labels_of(rows[order]) if corpus.manifest.get("tags") else {}
    inv = np.empty_like(order)
    inv[order] = np.arange(len(order))
    tags = [", ".join(f"{k}={v[inv[i]]}" for k, v in tags_sorted.items())
            for i in range(len(rows))]
    return who, tags


def _supports(corpus, rows: np.ndarray, weights: np.ndarray) -> list[list[tuple]]:
    """Per step, (who, tags, weight) of its supporting rows: rows (T, m) -1 padded."""
    flat = np.unique(rows[rows >= 0])
    who, tags = _who(corpus, flat)
    at = {int(r): i for i, r in enumerate(flat)}
    return [[(who[at[int(r)]], tags[at[int(r)]], float(w)) for r, w in zip(rr, ww) if r >= 0]
            for rr, ww in zip(rows, weights)]


def _labels(corpus, actions: np.ndarray) -> list[str]:
    names = list((corpus.action_space or {}).get("names") or [])
    if corpus.discrete:
        if len(names) == 1 and corpus.n_actions > 1:  # one column's name: name=i
            names = [f"{names[0]}={i}" for i in range(corpus.n_actions)]
        names = names if len(names) == corpus.n_actions else []
        return [names[int(a)] if int(a) < len(names) else f"action {int(a)}"
                for a in np.asarray(actions).reshape(-1)]
    return [num(np.asarray(a).reshape(-1).tolist(), 3) for a in actions]


def action_names(corpus) -> dict[int, str] | None:
    """{action: label} of a discrete corpus (the decisions chart's rows), else None."""
    if not corpus.discrete:
        return None
    return dict(enumerate(_labels(corpus, np.arange(corpus.n_actions))))


def audit_episode(corpus, path, episode: int, upper: np.ndarray) -> Episode:
    """Episode ``episode`` of an audit log; ``upper`` (T,) its OOD band, replayed by the
    caller with the session's monitor settings."""
    recorded = read_audit_episode(path, episode)  # the audit log's one reader
    residual, actions, values = recorded.residuals, recorded.actions, recorded.values
    flagged, rows, weights = recorded.ood, recorded.support_rows, recorded.support_weights
    first = actions.reshape(len(actions), -1)[:, 0].astype(np.float64)
    return Episode(f"episode {episode}", f"{episode}", residual, upper, flagged, first,
                   _labels(corpus, actions), _supports(corpus, rows, weights),
                   value=None if np.isnan(values).all() else values,
                   steps=np.arange(len(residual)))


def steps_episodes(corpus, path, typical: dict) -> list[Episode]:
    """The episodes of an ``aoc evaluate --steps`` file; a step is flagged when its residual is
    above the corpus's typical p99 (the band drawn: p50 to p99)."""
    by: dict[int, list[dict]] = {}
    with open(path) as fh:
        for n, line in enumerate(fh, 1):
            if not line.strip():
                continue
            try:
                rec = json.loads(line)
                by.setdefault(int(rec["episode"]), []).append(rec)
            except (ValueError, KeyError, TypeError):
                raise BadInput(path, f"{path} line {n} is not a step of "
                               f"`{call('evaluate', steps=True)}`", where=f"line {n}") from None
    if not by:
        raise AocError(f"{path} holds no steps")
    p99 = typical.get("p99") or np.inf
    out = []
    for e, recs in sorted(by.items()):
        recs.sort(key=lambda r: r["step"])
        residual = np.array([r["residual"] for r in recs], np.float64)
        dec = np.array([np.asarray(r["decision"], np.float64).reshape(-1)[0] for r in recs])
        logged = np.array([np.asarray(r["logged"], np.float64).reshape(-1)[0] for r in recs])
        m = max(len(r["support"]) for r in recs)
        rows = np.full((len(recs), m), -1, np.int64)
        weights = np.zeros((len(recs), m))
        for t, r in enumerate(recs):
            rows[t, :len(r["support"])] = [s["row"] for s in r["support"]]
            weights[t, :len(r["support"])] = [s["weight"] for s in r["support"]]
        eid = recs[0].get("episode_id")
        decided = np.array([r["decision"] for r in recs])
        out.append(Episode(
            f"episode {e}" + (f" ({eid})" if eid is not None else ""), f"{e}", residual,
            np.full(len(recs), p99), residual > p99,
            dec, _labels(corpus, decided), _supports(corpus, rows, weights), logged=logged,
            value=np.array([r.get("v_hat", np.nan) for r in recs], np.float64)
            if "v_hat" in recs[0] else None, steps=np.array([r["step"] for r in recs])))
    return out


def _decisions_chart(ep: Episode, steps: np.ndarray, href: list[str]) -> tuple[str, int]:
    """The decisions over time (and the logged actions): the first coordinate of a continuous
    action; a discrete corpus's actions one labelled row each, in the order of their numbers.
    And its left margin (the residual chart's, so that the steps line up)."""
    decision, logged, yticks, height = ep.decision, ep.logged, None, 150
    title = "decisions over time (the first coordinate of an action)"
    if ep.actions is not None:
        taken = np.concatenate([decision, [] if logged is None else logged]).astype(np.int64)
        order = {int(a): i for i, a in enumerate(np.unique(taken))}
        decision = np.array([order[int(a)] for a in decision], np.float64)
        logged = None if logged is None else \
            np.array([order[int(a)] for a in logged], np.float64)
        yticks = [(i, ep.actions.get(a, f"action {a}")) for a, i in order.items()]
        height = max(height, 46 + 16 * len(order))
        title = "decisions over time (one row per action taken)"
    series = [{"y": decision, "colour": "#009E73", "label": "decision"}]
    if logged is not None:
        series.append({"y": logged, "colour": "#555", "dash": True, "label": "logged"})
    points = [{"x": float(t), "y": float(d), "colour": "#009E73", "href": h,
               "label": f"step {int(t)}: {lab}"}
              for t, d, h, lab in zip(steps, decision, href, ep.labels)]
    left = tick_margin(yticks)
    return chart(steps, series, width=1000, height=height, points=points, title=title,
                 ylabel="step", yticks=yticks, left=left), left


def episode_section(ep: Episode, typical: dict, detail: int | None = None) -> str:
    """Charts and step sections of one episode; ``detail`` a step whose full decision
    section (``#decision``) is on the page."""
    steps = ep.steps if ep.steps is not None else np.arange(len(ep.residual))
    upper = np.where(np.isfinite(ep.upper), ep.upper, np.nan)
    href = [f"#step-{ep.key}-{int(t)}" for t in steps]
    points = [{"x": float(t), "y": float(r), "colour": "#D55E00", "shape": "x", "href": h,
               "label": f"step {int(t)}: flagged, residual {r:.3g}"}
              for t, r, h, f in zip(steps, ep.residual, href, ep.flagged) if f]
    band = (np.zeros(len(steps)), upper, "OOD band")
    dec_chart, left = _decisions_chart(ep, steps, href)
    res_chart = chart(steps, [{"y": ep.residual, "colour": "#0072B2", "label": "residual"},
                              {"y": upper, "colour": "#777", "dash": True,
                               "label": "OOD band (upper edge)"}],
                      width=1000, height=200, band=band, points=points,
                      title=f"{ep.title}: residual over time; flagged steps marked x "
                            f"(typical p50 {num(typical.get('p50'), 3)})", ylabel="step",
                      left=left)
    rows, flag = [], ' &middot; <b class="bad">flagged</b>'
    for i, t in enumerate(steps):
        sup = "; ".join(f"{esc(w)} ({esc(tg)}) {wt:.0%}" if tg else f"{esc(w)} {wt:.0%}"
                        for w, tg, wt in ep.support[i])
        more = ' <a href="#decision">full explanation below</a>' if detail == int(t) else ""
        value = "" if ep.value is None else f" &middot; value {num(ep.value[i])}"
        rows.append(
            f'<div class="step{" flag" if ep.flagged[i] else ""}" id="{esc(href[i][1:])}">'
            f"<b>step {int(t)}</b>: {esc(ep.labels[i])}{value} &middot; residual "
            f"{num(ep.residual[i], 3)}{flag if ep.flagged[i] else ''}"
            f"{more}<br><span class=\"muted\">supported by: {sup}</span></div>")
    return (f'<section id="episode-{esc(ep.key)}"><h2>{esc(ep.title)}</h2>{res_chart}'
            f'{dec_chart}<h3>Steps</h3>{"".join(rows)}</section>')
