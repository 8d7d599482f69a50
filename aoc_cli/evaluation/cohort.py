"""The cohort report's data (``aoc evaluate --html``): an evaluation's summary and its per-step
results shaped into what the report draws (:mod:`aoc_cli.report.cohort` renders it; nothing
here writes HTML).

* ``forest``: every estimator's value of each policy and of the logged behaviour, with its
  interval, or the reason it is withheld (never a number the log does not support);
* ``support``: the ESS at each step, the share of the policy's episodes the log follows, the
  propensity model's calibration bins;
* ``agreement``: the logged against the decided action (discrete: one cell per pair of actions,
  by their labels; continuous: the first coordinate's quantile bins), and the agreement by a tag
  or by an observation feature's (or a numeric column's) quartiles (``by``);
* ``residual``: the decisions' residuals against the corpus's typical residual;
* ``top``: the steps where the policy departs most from the logged action, then those resting
  on the thinnest support (the largest residual against the typical).
"""

from __future__ import annotations

import numpy as np

from aoc_cli.errors import BadSetting, param
from aoc_cli.evaluation.step_scores import StepScores
from aoc_cli.store import action_labels

#: Steps listed (``--top``) when not given.
TOP = 20
#: Quantile groups of a numeric ``--by``.
QUANTILES = 4
#: Bins of the residual's histogram, and of a continuous action's agreement map.
RESIDUAL_BINS = 24
ACTION_BINS = 6


def labels_of(corpus) -> list[str] | None:
    """Each discrete action's label (a one-name space: ``name=i``; else ``action i``)."""
    if not corpus.discrete:
        return None
    named = action_labels(corpus.action_space)
    if named:
        return named
    names = list((corpus.action_space or {}).get("names") or [])
    stem = names[0] if len(names) == 1 else "action"
    return [f"{stem}={i}" if names else f"action {i}" for i in range(corpus.n_actions)]


def verdict_line(summary: dict) -> str:
    """One line: the OPE's verdict (value mode), else what the decisions' agreement shows."""
    if summary.get("verdict"):
        return f"{summary['verdict'][0].upper()}{summary['verdict'][1:]}."
    steps = summary["steps"]
    if summary["mode"] == "imitation":
        if summary.get("accuracy") is not None:
            base = summary.get("majority_accuracy")
            more = "" if base is None else f" (the most frequent action alone: {base:.1%})"
            return (f"Imitation: the decision is the logged action at {summary['accuracy']:.1%}"
                    f" of {steps} steps{more}; AUC {summary.get('auc') or float('nan'):.3f}.")
        return f"Imitation of continuous actions: R^2 {summary.get('r2', float('nan')):.3f} " \
               f"over {steps} steps."
    return (f"Value mode, no offline policy evaluation on this log; the decision is the logged "
            f"action at {summary.get('agreement') or 0:.1%} of {steps} steps.")


def forest(summary: dict) -> list[dict]:
    """One row per (policy, estimator): {policy, estimator, estimate, low, high, reason}."""
    rows = []
    policies = [("aoc", summary)] + [(n, r) for n, r in summary.get("baselines", {}).items()
                                     if r.get("policy_value")]
    for name, rec in policies:
        for est, e in (rec.get("policy_value") or {}).items():
            rows.append({"policy": name, "estimator": est, "estimate": e.get("estimate"),
                         "low": e.get("low"), "high": e.get("high"), "reason": e.get("reason")})
    own = summary.get("behaviour_value")
    if own:
        rows.append({"policy": "logged behaviour", "estimator": "mean return",
                     "estimate": own.get("estimate"), "low": own.get("low"),
                     "high": own.get("high"), "reason": own.get("reason")})
        if own.get("fqe") is not None:
            rows.append({"policy": "logged behaviour", "estimator": "fqe",
                         "estimate": own["fqe"], "low": None, "high": None, "reason": None})
    return rows


def support(summary: dict) -> dict | None:
    """The ESS per step, the share reached, the propensity model's calibration (value mode
    with an OPE); None without one."""
    if "policy_value" not in summary:
        return None
    sup = summary.get("support") or {}
    ope = summary.get("ope") or {}
    model = ope.get("propensity_model") or {}
    return {"ess": summary.get("ess"), "ess_per_step": sup.get("ess_per_step") or [],
            "reached": sup.get("reached"), "first_step_weight": sup.get("first_step_weight"),
            "episodes": summary["episodes"], "propensity": ope.get("propensity"),
            "calibration": model.get("calibration"), "ece": model.get("ece"),
            "log_loss": model.get("log_loss"),
            "log_loss_frequencies": model.get("log_loss_frequencies")}


def _first(a) -> np.ndarray:
    a = np.asarray(a, np.float64)
    return a.reshape(len(a), -1)[:, 0]


def agreement(res: StepScores, corpus) -> dict:
    """The logged against the decided action: {"rows", "columns" (labels), "counts" (R, C),
    "kind"}; discrete: the actions logged or decided, by their labels."""
    if corpus.discrete:
        labels = labels_of(corpus)
        logged, decided = np.asarray(res.logged, np.int64), np.asarray(res.decided, np.int64)
        used = np.unique(np.concatenate([logged, decided]))
        at = {int(a): i for i, a in enumerate(used)}
        counts = np.zeros((len(used), len(used)), np.int64)
        np.add.at(counts, ([at[int(a)] for a in logged], [at[int(a)] for a in decided]), 1)
        names = [labels[int(a)] for a in used]
        return {"kind": "discrete", "actions": used.tolist(), "rows": names, "columns": names,
                "counts": counts.tolist(), "share": float(np.mean(logged == decided))}
    lo_first, de_first = _first(res.logged), _first(res.decided)
    edges = np.unique(np.quantile(np.concatenate([lo_first, de_first]),
                                  np.linspace(0, 1, ACTION_BINS + 1)))
    if len(edges) < 2:
        edges = np.array([edges[0] - 0.5, edges[0] + 0.5])
    inner = edges[1:-1]
    li, di = np.searchsorted(inner, lo_first, "right"), np.searchsorted(inner, de_first, "right")
    n = len(edges) - 1
    counts = np.zeros((n, n), np.int64)
    np.add.at(counts, (li, di), 1)
    names = [f"{edges[i]:.3g} to {edges[i + 1]:.3g}" for i in range(n)]
    return {"kind": "continuous", "actions": list(range(n)), "rows": names, "columns": names,
            "counts": counts.tolist(), "share": float(np.mean(li == di))}


def _agrees(res: StepScores, corpus) -> np.ndarray:
    """(S,) per step: 1 where the decision is the logged action (discrete), else minus the
    first coordinate's distance."""
    if corpus.discrete:
        return (np.asarray(res.logged) == np.asarray(res.decided)).astype(np.float64)
    return -np.abs(_first(res.logged) - _first(res.decided))


def check_by(data, by: str | None) -> None:
    """Refuse a ``by`` that is no tag, observation feature or numeric column of ``data``."""
    obs_names = list((data.observation_space or {}).get("names") or [])
    known = sorted(set(data.manifest.get("tags") or {}) | set(obs_names)
                   | set(data.manifest.get("columns") or []))
    if by is not None and by not in known:
        raise BadSetting("by", by, f"{param('by')} {by!r} is no tag, observation feature or "
                         f"numeric column of corpus {data.name!r} (it has: "
                         f"{', '.join(known[:12]) or 'none'}{', ...' if len(known) > 12 else ''})")


def by_groups(res: StepScores, data, corpus, by: str | None) -> dict | None:
    """Agreement by ``by``: a tag of the held-out corpus (one group per value), an observation
    feature or a numeric column (its quartiles over the held-out steps). None: no ``by``."""
    if by is None:
        return None
    rows = np.asarray(res.row, np.int64)
    obs_names = list((data.observation_space or {}).get("names") or [])
    if by in (data.manifest.get("tags") or {}):
        codes, labels = data.tag(by)
        codes = np.asarray(codes)[rows]
        groups = [(labels[c], codes == c) for c in np.unique(codes)]
        what = f"tag {by}"
    elif by in obs_names or by in (data.manifest.get("columns") or []):
        values = np.asarray(data.observations, np.float64)[rows, obs_names.index(by)] \
            if by in obs_names else np.asarray(data.column(by), np.float64)[rows]
        edges = np.unique(np.nanquantile(values, np.linspace(0, 1, QUANTILES + 1)))
        which = np.searchsorted(edges[1:-1], values, "right")
        groups = [(f"{edges[q]:.4g} to {edges[q + 1]:.4g}", which == q)
                  for q in range(max(1, len(edges) - 1))]
        what = f"{by} ({'quartiles' if len(edges) == QUANTILES + 1 else 'quantile groups'})"
    else:
        check_by(data, by)
    agrees = _agrees(res, corpus)
    residual = np.asarray(res.residual, np.float64)
    out = []
    for label, mask in groups:
        if not mask.any():
            continue
        out.append({"group": str(label), "steps": int(mask.sum()),
                    "agreement": float(agrees[mask].mean()) if corpus.discrete else None,
                    "distance": None if corpus.discrete else float(-agrees[mask].mean()),
                    "residual_median": float(np.median(residual[mask]))})
    return {"by": what, "groups": out}


def residuals(res: StepScores, typical: dict) -> dict:
    """The residuals' histogram (``edges`` (B + 1,), ``counts`` (B,)) and the typical p50,
    p90, p99 of the corpus."""
    r = np.asarray(res.residual, np.float64)
    hi = max(float(r.max()) if len(r) else 1.0, float(typical.get("p99") or 0.0)) * 1.02
    counts, edges = np.histogram(r, bins=RESIDUAL_BINS, range=(0.0, hi or 1.0))
    return {"edges": edges.tolist(), "counts": counts.tolist(),
            "typical": {k: typical.get(k) for k in ("p50", "p90", "p99")},
            "above_p99": int(np.sum(r > (typical.get("p99") or np.inf)))}


def departure(res: StepScores, corpus, span=None) -> tuple[np.ndarray, str]:
    """(S,) how far each decision departs from the logged action (0 where they agree), and
    what it measures: value mode, v_hat(decided) - v_hat(logged); discrete imitation, the
    decided action's score less the logged one's; continuous, the actions' distance (in
    units of the action range ``span`` where given)."""
    logged, decided = np.asarray(res.logged), np.asarray(res.decided)
    if corpus.discrete:
        differs = logged != decided
        if res.decided_value is not None and res.v_hat is not None:
            gap = np.asarray(res.decided_value, np.float64) - np.asarray(res.v_hat, np.float64)
            return np.where(differs, np.abs(gap), 0.0), "v_hat(decided) - v_hat(logged)"
        if res.scores is not None:
            s = np.asarray(res.scores, np.float64)
            idx = np.arange(len(s))
            return np.where(differs, s[idx, decided] - s[idx, logged], 0.0), \
                "score(decided) - score(logged)"
        return differs.astype(np.float64), "decided differs"
    d = np.asarray(decided, np.float64).reshape(len(decided), -1) - \
        np.asarray(logged, np.float64).reshape(len(logged), -1)
    if span is not None:
        d = d / np.asarray(span, np.float64)
    return np.sqrt((d ** 2).sum(1)), "action distance" + (" (of the range)" if span is not None
                                                          else "")


def top_steps(res: StepScores, data, corpus, typical: float | None, top: int = TOP) -> dict:
    """The ``top`` steps to read: about half where the decision departs most from the logged
    action (of those that depart), the rest of the largest residual against ``typical``
    (the thinnest support); each {episode, episode_id, step, row, logged, decided, residual,
    ratio, departure, why}."""
    if top < 0:
        raise BadSetting("top", top, f"{param('top')} must be >= 0, got {top}")
    span = None
    if not corpus.discrete:
        acts = np.asarray(corpus.actions, np.float64).reshape(corpus.n_rows, -1)
        span = np.maximum(acts.max(0) - acts.min(0), 1e-12)
    gap, measure = departure(res, corpus, span)
    residual = np.asarray(res.residual, np.float64)
    ratio = residual / typical if typical else residual
    order_gap = [i for i in np.argsort(-gap, kind="stable") if gap[i] > 0]
    order_res = list(np.argsort(-ratio, kind="stable"))
    want_gap = min(len(order_gap), (top + 1) // 2)
    chosen: dict[int, str] = {int(i): "departs" for i in order_gap[:want_gap]}
    for i in order_res:
        if len(chosen) >= top:
            break
        chosen.setdefault(int(i), "thin support")
    for i in order_gap[want_gap:]:          # fewer steps than asked: fill with departures
        if len(chosen) >= top:
            break
        chosen.setdefault(int(i), "departs")
    labels = labels_of(corpus)
    ids = data.episode_ids

    def label(a):
        if labels is not None:
            return labels[int(np.asarray(a).reshape(-1)[0])]
        return "[" + ", ".join(f"{x:.3g}" for x in np.asarray(a, np.float64).reshape(-1)) + "]"

    steps = []
    for i, why in chosen.items():
        e = int(res.episode[i])
        steps.append({"index": i, "episode": e, "episode_id": None if ids is None else ids[e],
                      "step": int(res.step[i]), "row": int(res.row[i]),
                      "logged": label(res.logged[i]), "decided": label(res.decided[i]),
                      "residual": float(residual[i]),
                      "ratio": float(ratio[i]) if typical else None,
                      "departure": float(gap[i]), "why": why, "page": None})
    return {"measure": measure, "steps": steps}


def cohort(summary: dict, res: StepScores, corpus, data, typical: dict,
           by: str | None = None, top: int = TOP) -> dict:
    """Everything the cohort report draws (module docstring). ``typical``: the corpus's
    typical residuals {p50, p90, p99}."""
    return {"title": {k: summary.get(k) for k in ("corpus", "data", "model", "mode", "steps",
                                                    "episodes")},
            "verdict": verdict_line(summary),
            "warnings": list(summary.get("ope_warnings") or []),
            "forest": forest(summary), "support": support(summary),
            "agreement": agreement(res, corpus), "by": by_groups(res, data, corpus, by),
            "residual": residuals(res, typical),
            "top": top_steps(res, data, corpus, typical.get("p50"), top),
            "what_if": summary.get("what_if")}
