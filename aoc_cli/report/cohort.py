"""The cohort report (``aoc evaluate --html FILE``): one page a clinical team reads, built from
:func:`aoc_cli.evaluation.cohort.cohort`'s data. Sections: the verdict; the forest plot of
every estimator's value of each policy and of the logged behaviour (a withheld estimate drawn
as its reason); the log's support (ESS per step, the share reached, the propensity model's
calibration); agreement (logged against decided, and by a tag or a feature's quartiles); the
residuals against the typical residual; the steps to read, each linked to its decision page.

Self-contained like the decision pages (:func:`aoc_cli.report.html.page`: no script, a
Content-Security-Policy that fetches nothing); every user string escaped."""

from __future__ import annotations

from aoc_cli.report.charts import forest_plot, heatmap, histogram
from aoc_cli.report.html import esc, num, page
from aoc_cli.report.svg import chart

SECTIONS = ("verdict", "values", "support", "agreement", "residuals", "steps")


def _title(c: dict) -> str:
    t = c["title"]
    return (f"<h1>Evaluation of {esc(t['corpus'])} on {esc(t['data'])}</h1>"
            f'<p class="muted">model {esc(t["model"])} &middot; {esc(t["mode"])} mode &middot; '
            f"{t['steps']} steps of {t['episodes']} episodes &middot; written by aoc evaluate "
            "--html</p>")


def verdict_section(c: dict) -> str:
    warnings = "".join(f'<p class="warn">warning: {esc(w)}</p>' for w in c["warnings"])
    return (f'<section id="verdict"><p class="lede"><b>{esc(c["verdict"])}</b></p>'
            f"{warnings}</section>")


def values_section(c: dict) -> str:
    rows = c["forest"]
    if not rows:
        return ('<section id="values"><h2>Values of the policies</h2><p class="muted">No '
                "offline policy evaluation: it needs a value-mode model and a held-out log "
                "with rewards and discrete actions.</p></section>")
    table = "".join(
        f'<tr><td>{esc(r["policy"])}</td><td>{esc(r["estimator"])}</td>'
        + (f'<td>{num(r["estimate"])}</td><td>{num(r["low"])}</td><td>{num(r["high"])}</td>'
           '<td></td>' if r["estimate"] is not None else
           f'<td colspan="3" class="warn">withheld</td><td>{esc(r.get("reason"))}</td>')
        + "</tr>" for r in rows)
    return ('<section id="values"><h2>Values of the policies</h2><p class="muted">Each '
            "estimator's value of each policy with its 95% interval, beside the logged "
            "behaviour's mean return. An estimate the log does not support is withheld and "
            "drawn as its reason (docs/design.md, \"Offline policy evaluation: what is "
            f'shown").</p><div class="scroll">{forest_plot(rows)}</div><table class="forest-'
            'table"><tr><th>policy</th><th>estimator</th><th>estimate</th><th>low</th><th>'
            f"high</th><th>why withheld</th></tr>{table}</table></section>")


def support_section(c: dict) -> str:
    s = c["support"]
    if s is None:
        return ('<section id="support"><h2>Support in the log</h2><p class="muted">No '
                "offline policy evaluation on this log, so no importance weights: the "
                "residuals below say how far the decisions extrapolate.</p></section>")
    parts = [f'<section id="support"><h2>Support in the log</h2><p>Effective sample size '
             f'<b>{num(s["ess"])}</b> of {s["episodes"]} episodes; the log follows '
             f'<b>{_pct(s["reached"])}</b> of the policy\'s episodes to their end; mean '
             f'first-step weight {num(s["first_step_weight"], 3)} (about 1 when the '
             f'propensities are the behaviour\'s). Propensities: {esc(s["propensity"])}.</p>']
    ess = s["ess_per_step"]
    if ess:
        parts.append(chart(list(range(len(ess))), [{"y": ess, "colour": "#0072B2",
                                                    "label": "ESS of the running weights"}],
                           width=640, height=170, title="effective sample size at each step",
                           ylabel="step"))
    cal = s.get("calibration")
    if cal:
        xs = [b["predicted"] for b in cal]
        parts.append(chart(xs, [{"y": [b["observed"] for b in cal], "colour": "#009E73",
                                 "label": "observed share"},
                                {"y": xs, "colour": "#777", "dash": True,
                                 "label": "perfect calibration"}],
                           width=420, height=200,
                           title=f"propensity model's calibration (ECE {num(s['ece'], 3)})",
                           ylabel="predicted probability",
                           points=[{"x": b["predicted"], "y": b["observed"], "colour": "#009E73",
                                    "label": f"{b['pairs']} (step, action) pairs"}
                                   for b in cal]))
        parts.append(f'<p class="muted">Held-out log-loss {num(s["log_loss"])} (the action '
                     f'frequencies alone: {num(s["log_loss_frequencies"])}).</p>')
    parts.append("</section>")
    return "".join(parts)


def _pct(x) -> str:
    return "-" if x is None else f"{x:.0%}"


def agreement_section(c: dict) -> str:
    a = c["agreement"]
    what = "the same action" if a["kind"] == "discrete" else \
        "the same bin of the first action coordinate"
    key = ""
    long = any(len(t) > 16 for t in a["rows"])
    if long:
        key = ('<table class="key"><tr><th>action</th><th>label</th></tr>' + "".join(
            f"<tr><td>{n}</td><td>{esc(t)}</td></tr>" for n, t in zip(a["actions"], a["rows"]))
            + "</table>")
    parts = [f'<section id="agreement"><h2>Where the policy differs from the log</h2><p>The '
             f"decision is {what} as logged at <b>{a['share']:.1%}</b> of the steps. Each row: "
             "what the policy decides where that action was logged (shaded by its share of "
             f'the row; the diagonal outlined).</p><div class="scroll">'
             f'{heatmap(a["rows"], a["columns"], a["counts"], a["actions"])}</div>{key}']
    by = c.get("by")
    if by:
        metric = "agreement" if by["groups"] and by["groups"][0]["agreement"] is not None \
            else "distance"
        rows = "".join(
            f'<tr><td>{esc(g["group"])}</td><td>{g["steps"]}</td><td>'
            + (f'<span class="bar pos" style="width:{int(80 * g["agreement"]) + 1}px"></span> '
               f'{g["agreement"]:.1%}' if metric == "agreement" else num(g["distance"], 3))
            + f'</td><td>{num(g["residual_median"], 3)}</td></tr>' for g in by["groups"])
        label = "agreement" if metric == "agreement" else "mean |decided - logged|"
        parts.append(f'<h3 id="by">By {esc(by["by"])}</h3><table class="by"><tr><th>group'
                     f"</th><th>steps</th><th>{label}</th><th>median residual</th></tr>"
                     f"{rows}</table>")
    parts.append("</section>")
    return "".join(parts)


def residual_section(c: dict) -> str:
    r = c["residual"]
    t = r["typical"]
    marks = {f"typical p{q}": t.get(f"p{q}") for q in (50, 90, 99)}
    return ('<section id="residuals"><h2>How far the decisions extrapolate</h2><p>The '
            "corpus residual of each decision against the corpus's typical residual (the "
            f"residuals of its own rows held out): <b>{r['above_p99']}</b> decisions above the "
            f'typical p99.</p>{histogram(r["edges"], r["counts"], marks, xlabel="residual")}'
            "</section>")


def steps_section(c: dict, linked: bool = True) -> str:
    top = c["top"]
    if not top["steps"]:
        return '<section id="steps"><h2>Steps to read</h2><p>None asked.</p></section>'
    rows = []
    for s in top["steps"]:
        who = f"{s['episode']}" + (f" ({s['episode_id']})" if s["episode_id"] is not None
                                   else "")
        at = f"episode {who}, step {s['step']}"
        link = f'<a href="{esc(s["page"])}">{esc(at)}</a>' if linked and s.get("page") \
            else esc(at)
        ratio = "" if s["ratio"] is None else f" ({s['ratio']:.2g}x typical)"
        rows.append(f'<tr class="top-step" data-why="{esc(s["why"])}"><td>{link}</td><td>'
                    f'{esc(s["why"])}</td><td>{esc(s["logged"])}</td><td>{esc(s["decided"])}'
                    f'</td><td>{num(s["departure"], 3)}</td><td>{num(s["residual"], 3)}'
                    f"{ratio}</td></tr>")
    return (f'<section id="steps"><h2>Steps to read</h2><p>The steps where the policy departs '
            f"most from the logged action ({esc(top['measure'])}), then those resting on the "
            "thinnest support (the largest residual against the typical); each links to its "
            'decision page.</p><table class="steps"><tr><th>step</th><th>why listed</th><th>'
            "logged</th><th>decided</th><th>departure</th><th>residual</th></tr>"
            f'{"".join(rows)}</table></section>')


def what_if_section(c: dict) -> str:
    w = c.get("what_if")
    if not w:
        return ""
    return (f'<section id="what-if"><h2>Without {esc(w["without"]["label"])}</h2><p>'
            f"{w['without']['rows']} rows of {w['without']['episodes']} episodes removed: "
            f"{w['flipped']} of {w['steps']} decisions change ({w['flip_share']:.1%}).</p>"
            "</section>")


def body(c: dict, linked: bool = True) -> str:
    """The report's HTML body (no document shell): every section in order."""
    return "".join([_title(c), verdict_section(c), values_section(c), support_section(c),
                    agreement_section(c), residual_section(c), what_if_section(c),
                    steps_section(c, linked)])


def cohort_page(c: dict) -> str:
    """The whole self-contained document."""
    t = c["title"]
    return page(f"aoc evaluate: {t['corpus']} on {t['data']}", body(c))
