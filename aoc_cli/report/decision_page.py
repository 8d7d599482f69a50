"""The decision page (``aoc explain ... --html FILE``): a decision in words, the measured
values of the query and of its supporting rows (:mod:`aoc_cli.report.values`), one card per
supporting row with its history beside the query's, the contrast and the what-if.

Input: the records of :func:`aoc_cli.explanation.decisions.explain_decisions` (with
``attribution`` and ``query_history``), the corpus, and the corpus a logged query was read
from (its imputed cells and columns). Every user string is escaped
(:func:`aoc_cli.report.html.esc`); the page has no script.
"""

from __future__ import annotations

import numpy as np

from aoc_cli.envs import TASKS, collected_task
from aoc_cli.report.html import esc, num
from aoc_cli.report.svg import PALETTE, chart
from aoc_cli.report.values import (MAX_COLUMNS, Values, card_values, columns_of, history_rows,
                                   imputed_mask, legend, shown_features, values_table)

#: Observation features drawn on a card (chosen by attribution).
TOP_FEATURES = 3
#: Features listed with attribution bars on a card.
TOP_BARS = 5


class PageContext:
    """What every section of a page reads from the corpus once: feature and action names,
    the observations' mean and std (the cards draw standardised features), the imputed cells
    and numeric columns; ``source`` the corpus logged queries were read from (``--data``)."""

    def __init__(self, corpus, source=None):
        self.corpus = corpus
        self.source = source
        space = corpus.observation_space or {}
        d_o = corpus.observation_dim
        self.obs_names = list(space.get("names") or [f"obs_{i}" for i in range(d_o)])
        names = list((corpus.action_space or {}).get("names") or [])
        # a discrete space's names label its actions when there is one per action; one name
        # (a CSV's action column, ward's act_oxygen) labels them name=i
        if corpus.discrete and len(names) == 1 and corpus.n_actions > 1:
            names = [f"{names[0]}={i}" for i in range(corpus.n_actions)]
        self.action_names = names if not corpus.discrete or len(names) == corpus.n_actions \
            else []
        obs = np.asarray(corpus.observations, np.float64)
        self.mean = obs.mean(0)
        self.std = np.where(obs.std(0) > 1e-9, obs.std(0), 1.0)
        self.unit = "patients" if getattr(corpus, "episode_ids", None) is not None \
            else "episodes"
        self.imputed = imputed_mask(corpus)
        self.rule = (getattr(corpus, "preprocessing", None) or {}).get("impute", {}).get("rule")
        self.columns = list(corpus.manifest.get("columns") or [])[:MAX_COLUMNS]
        task = TASKS.get(collected_task(corpus))
        self.units = task.extra.get("units") if task is not None else None

    def query(self, rec: dict) -> tuple[Values, np.ndarray | None, bool]:
        """The decision's query as a column of values, its history's imputed cells (L, d_o)
        (None: none or not known), and whether its cells' imputation is known: the record's
        ``query_imputed`` (a JSONL query's nulls), or read from the ``--data`` corpus when
        the record is a step of it, else unknown."""
        obs = np.asarray(rec["observation"], np.float64)
        if rec.get("query_imputed") is not None:  # a JSONL query's null cells, filled
            hist = rec.get("query_history_imputed")
            return (Values("this step", "the query", obs, np.asarray(rec["query_imputed"], bool),
                           {}), None if not hist else np.asarray(hist, bool), True)
        src, row = self.source, rec.get("row")
        if src is None or row is None or rec.get("data") != src.name:
            return Values("this step", "the query", obs, None, {}), None, False
        mask = imputed_mask(src)
        rows = np.asarray([row], np.int64)
        length = len((rec.get("query_history") or {}).get("present") or [])
        hist = None if mask is None or not length else mask[history_rows(rows, length)[0]]
        return (Values("this step", "the query", obs, None if mask is None else mask[row],
                       columns_of(src, rows, self.columns)[0]), hist, True)

    def action(self, a) -> str:
        """An action as a person reads it: a discrete action's label, else its numbers."""
        if isinstance(a, int) or (isinstance(a, float) and self.corpus.discrete):
            i = int(a)
            label = self.action_names[i] if i < len(self.action_names) else None
            return f"{label} ({i})" if label else f"action {i}"
        return num(a, 3)


def residual_words(residual: float, typical: float | None) -> tuple[str, str]:
    """("residual 0.4x typical", css class) for a residual against the corpus's typical."""
    if not typical:
        return f"residual {num(residual, 3)}", "muted"
    ratio = residual / typical
    if ratio <= 1.0:
        return f"residual {ratio:.2g}x typical (within the corpus's usual range)", "ok"
    if ratio <= 3.0:
        return f"residual {ratio:.2g}x typical (somewhat unusual)", "warn"
    return f"residual {ratio:.2g}x typical (far from every past case: it extrapolates)", "bad"


def lede(rec: dict, ctx: PageContext) -> str:
    """The decision in one sentence a clinician reads."""
    episodes = {s["episode"] for s in rec["support"]}
    words, css = residual_words(rec["residual"], rec.get("typical_residual"))
    value = "" if rec.get("value") is None else f"; expected value {num(rec['value'])}"
    if rec.get("scores") is not None:  # discrete imitation: the sum over the rows of weight x label
        value = f"; score {rec['scores'][int(rec['action'])]:.0%} (weight x label over the rows)"
    role = rec.get("role", "decision")
    verb = "Recommended" if role == "decision" else "Explained"
    return (f'<p class="lede"><b>{esc(verb)}: {esc(ctx.action(rec["action"]))}</b>, '
            f"supported by {len(episodes)} past {esc(ctx.unit)} ({len(rec['support'])} "
            f'rows){esc(value)}; <span class="{css}">{esc(words)}</span>.</p>')


def importance(rec: dict, d_o: int) -> np.ndarray:
    """(d_o,) how much each observation feature made the supporting rows count: the rows'
    weighted absolute attributions of the feature, now and in the history."""
    total = np.zeros(d_o)
    for s in rec["support"]:
        a = s.get("attribution")
        if not a:
            continue
        total += s["weight"] * np.abs(np.asarray(a["observation"]))
        if a.get("history") is not None:
            total += s["weight"] * np.abs(np.asarray(a["history"])[:, :d_o]).sum(0)
    return total


def _bars(s: dict, ctx: PageContext, names_step: list[str], names_action: list[str]) -> str:
    """The row's largest attributions as signed bars."""
    a = s.get("attribution")
    if not a:
        return ""
    items = [(ctx.obs_names[i], v) for i, v in enumerate(a["observation"])]
    for i, v in enumerate(a.get("action") or []):
        items.append((names_action[i] if i < len(names_action) else f"action input {i}", v))
    hist = a.get("history")
    if hist is not None:
        lags = len(hist)
        for lag, row in enumerate(hist):
            for j, v in enumerate(row):
                name = names_step[j] if j < len(names_step) else f"feature {j}"
                items.append((f"{name} (t-{lags - lag})", v))
    items.sort(key=lambda kv: -abs(kv[1]))
    top = items[:TOP_BARS]
    scale = max((abs(v) for _, v in top), default=1.0) or 1.0
    rows = "".join(
        f'<tr><td>{esc(name)}</td><td><span class="bar {"pos" if v >= 0 else "neg"}" '
        f'style="width:{int(60 * abs(v) / scale) + 1}px"></span> {num(v, 3)}</td></tr>'
        for name, v in top)
    return (f'<table class="kv bars"><tr><th colspan="2">what made it count (projection '
            f'{num(a["projection"], 3)})</th></tr>{rows}</table>')


def _series(ctx: PageContext, obs_hist, present, now, features) -> list[np.ndarray]:
    """Standardised values of ``features`` over the history steps and now: (L + 1,) each
    (L may be 0: a model that reads the current step only)."""
    obs_hist = np.asarray(obs_hist, np.float64).reshape(len(present), len(ctx.mean))
    out = []
    for j in features:
        h = (obs_hist[:, j] - ctx.mean[j]) / ctx.std[j]
        h = np.where(np.asarray(present, bool), h, np.nan)
        out.append(np.append(h, (float(now[j]) - ctx.mean[j]) / ctx.std[j]))
    return out


def _actions(acts, present, now) -> np.ndarray:
    a = np.asarray(acts, np.float64)
    a = a.reshape(len(a), -1)[:, 0] if a.size else np.zeros(0)
    a = np.where(np.asarray(present, bool), a, np.nan)
    now = np.asarray(now, np.float64).reshape(-1)
    return np.append(a, now[0] if now.size else np.nan)


def _imputed_points(x, series, imputed, features, colour_of, label: str) -> list[dict]:
    """Hollow markers on a chart where a drawn value was imputed: ``imputed`` (L + 1, d_o)."""
    if imputed is None:
        return []
    return [{"x": float(x[t]), "y": float(y[t]), "colour": colour_of(i), "shape": "ring",
             "label": f"{label}: imputed"}
            for i, (j, y) in enumerate(zip(features, series))
            for t in np.flatnonzero(imputed[:, j]) if np.isfinite(y[t])]


def card(s: dict, hist: dict, row: Values, query: dict, qvals: Values, ctx: PageContext,
         features, names: dict) -> str:
    """One supporting row: who, when, what, how much, its values against the query's, and
    (a model with a history) its history beside the query's. ``hist`` and ``query`` hold
    ``imputed`` (L + 1, d_o) or None: the drawn cells imputed at ingest."""
    who = s.get("episode_id") if s.get("episode_id") is not None else f"episode {s['episode']}"
    tags = ", ".join(f"{k}={v}" for k, v in s["tags"].items())
    value = "" if s.get("value") is None else f" &middot; value {num(s['value'])}"
    plots = ""
    if len(query["present"]):  # a history to draw (a model of history length 0 reads none)
        x = np.arange(-len(query["present"]), 1)
        q = _series(ctx, query["observations"], query["present"], query["observation"],
                    features)
        r = _series(ctx, hist["observations"], hist["present"], row.observation, features)
        series = []
        for i, j in enumerate(features):
            colour = PALETTE[i % len(PALETTE)]
            series.append({"y": r[i], "colour": colour, "label": ctx.obs_names[j]})
            series.append({"y": q[i], "colour": colour, "dash": True, "label": ""})
        rings = _imputed_points(x, r, hist.get("imputed"), features,
                                lambda i: PALETTE[i % len(PALETTE)], "row") + \
            _imputed_points(x, q, query.get("imputed"), features,
                            lambda i: PALETTE[i % len(PALETTE)], "query")
        title = "history: row solid, query dashed" + ("; o imputed" if rings else "")
        plots = chart(x, series, title=title, height=150, ylabel="step (values standardised)",
                      points=rings)
        plots += chart(x, [{"y": _actions(hist["actions"], hist["present"], s["action"]),
                            "colour": "#333", "label": "row's actions"},
                           {"y": _actions(query["actions"], query["present"], query["action"]),
                            "colour": "#333", "dash": True, "label": "query's"}],
                       height=80, legend=True)
    return (f'<div class="card" data-row="{int(s["row"])}"><h3>{esc(who)}, step '
            f'{int(s["step"])}</h3><div class="kv">row {int(s["row"])}'
            f'{" &middot; " + esc(tags) if tags else ""}<br>action <b>'
            f'{esc(ctx.action(s["action"]))}</b>{value} &middot; weight <b>{s["weight"]:.1%}</b>'
            f'{_label(s, ctx)} &middot; distance '
            f'{num(s["distance"], 3)}</div>{card_values(features, ctx.obs_names, qvals, row)}'
            f'{plots}'
            f'{_bars(s, ctx, names.get("history_step") or [], names.get("action") or [])}</div>')


def _label(s: dict, ctx: PageContext) -> str:
    """A row's label (discrete imitation: its logged action smoothed towards the belief's
    probabilities; aoc_cli.belief.row_labels) as " · label a 68%, b 32%", else ""."""
    if "label" not in s:
        return ""
    return " &middot; label " + esc(", ".join(f"{ctx.action(a)} {p:.0%}"
                                             for a, p in enumerate(s["label"])))


def _support_table(support: list[dict], ctx: PageContext) -> str:
    rows = "".join(
        f"<tr><td>{esc(s.get('episode_id') if s.get('episode_id') is not None else s['episode'])}"
        f"</td><td>{int(s['step'])}</td><td>"
        f"{esc(', '.join(f'{k}={v}' for k, v in s['tags'].items()))}</td>"
        f"<td>{esc(ctx.action(s['action']))}</td><td>{num(s.get('value'))}</td>"
        f"<td>{s['weight']:.1%}{_label(s, ctx)}</td></tr>" for s in support)
    return ("<table><tr><th>episode</th><th>step</th><th>tags</th><th>action</th><th>value"
            f"</th><th>weight</th></tr>{rows}</table>")


def contrast_section(rec: dict, ctx: PageContext) -> str:
    c = rec.get("contrast")
    if not c:
        return ""
    figures = (f"score {c['score']:.0%}" if "score" in c else
               f"expected value {num(c['value'])}, residual {num(c['residual'], 3)}")
    return (f'<div class="contrast"><h3>Why not {esc(ctx.action(c["action"]))}?</h3>'
            f"<p>The best action not chosen ({esc(figures)}): {esc(c['why']['text'])}. "
            f"Its own supporting rows:</p>{_support_table(c['support'], ctx)}</div>")


def what_if_section(rec: dict, ctx: PageContext) -> str:
    w = rec.get("what_if")
    if not w:
        return ""
    action = f"another action: {ctx.action(w['action'])}" if w["action_changed"] \
        else "the same action"
    change = "the same decision, bit for bit" if w["unchanged"] else \
        f"{action}; {residual_words(w['residual'], rec.get('typical_residual'))[0]}"
    return (f'<div class="whatif"><h3>What if the corpus had no {esc(w["without"]["label"])}'
            f"?</h3><p>{w['without']['rows']} rows of {w['without']['episodes']} "
            f"{esc(ctx.unit)} removed ({len(w['support_removed'])} of them supported this "
            f"decision): {esc(change)}.</p>{_support_table(w['support'], ctx)}</div>")


def decision_section(rec: dict, ctx: PageContext, anchor: str = "decision") -> str:
    """One decision's section: the sentence, warnings, the values and the cards, the
    contrast, the what-if."""
    where = []
    if rec.get("episode") is not None:
        eid = rec.get("episode_id")
        where.append(f"episode {rec['episode']}" + (f" ({eid})" if eid is not None else ""))
    if rec.get("step") is not None:
        where.append(f"step {rec['step']}")
    title = f"{rec.get('role', 'decision')}" + (f", {', '.join(where)}" if where else "")
    parts = [f'<section id="{esc(anchor)}"><h2>{esc(title)}</h2>', lede(rec, ctx)]
    for w in rec.get("warnings", []):
        parts.append(f'<p class="warn">warning: {esc(w)}</p>')
    support = rec["support"]
    query = rec.get("query_history")
    if support and query is not None:
        parts.append(_subset(rec, ctx, dict(query, observation=rec["observation"],
                                            action=rec["action"])))
    elif support:
        parts.append(_support_table(support, ctx))
    parts.append(contrast_section(rec, ctx))
    parts.append(what_if_section(rec, ctx))
    parts.append("</section>")
    return "".join(parts)


def _subset(rec: dict, ctx: PageContext, query: dict) -> str:
    """The minimal corpus subset: the values table of the query and its rows, then a card
    per row."""
    corpus, support = ctx.corpus, rec["support"]
    weights = importance(rec, corpus.observation_dim)
    feats = list(np.argsort(-weights, kind="stable")[:TOP_FEATURES])
    names = rec.get("attribution_features") or {}
    rows = np.asarray(sorted(s["row"] for s in support), np.int64)
    length = len(query["present"])
    hist = corpus.history(rows, length)
    now = corpus.read("observations", rows)
    cols = columns_of(corpus, rows, ctx.columns)
    imp_now = hist_imp = None
    if ctx.imputed is not None:
        imp_now = ctx.imputed[rows]
        hist_imp = ctx.imputed[history_rows(rows, length)] & hist.mask[..., None]
    qvals, q_hist_imp, known = ctx.query(rec)
    if qvals.imputed is not None:
        q_hist_imp = np.zeros((length, corpus.observation_dim), bool) if q_hist_imp is None \
            else q_hist_imp & np.asarray(query["present"], bool)[:, None]
        query = dict(query, imputed=np.vstack([q_hist_imp, qvals.imputed[None]]))
    at = {int(r): i for i, r in enumerate(rows)}
    cards, columns = [], []
    for s in support:
        i = at[s["row"]]
        who = s.get("episode_id") if s.get("episode_id") is not None else f"episode {s['episode']}"
        row = Values(f"{who}, step {int(s['step'])}", f"weight {s['weight']:.1%}", now[i],
                     None if imp_now is None else imp_now[i], cols[i])
        columns.append(row)
        h = {"observations": hist.observations[i], "actions": hist.actions[i],
             "present": hist.mask[i],
             "imputed": None if hist_imp is None else np.vstack([hist_imp[i], imp_now[i][None]])}
        cards.append(card(s, h, row, query, qvals, ctx, feats, names))
    shown, note = shown_features(weights)
    any_imputed = ctx.imputed is not None and (bool(imp_now[:, shown].any()) or (
        qvals.imputed is not None and bool(qvals.imputed[shown].any())))
    table = values_table(shown, ctx.obs_names, ctx.std, qvals, columns, note) + \
        legend(ctx.rule, any_imputed, known, ctx.units)
    return (f"{table}<h3>The minimal corpus subset: {len(support)} past cases</h3>"
            f'<div class="cards">{"".join(cards)}</div>')
