"""What ``aoc evaluate`` prints of an evaluation's summary (:func:`aoc_cli.api.evaluate`):
JSON, one CSV row per method, or tables."""

from __future__ import annotations

from aoc_cli.ope.support import cell
from aoc_cli.cli.output import write_object, write_records

IMITATION_COLUMNS = ["method", "accuracy", "balanced_accuracy", "auc", "majority_accuracy",
                     "mae", "r2"]
VALUE_COLUMNS = ["method", "value_r2", "value_mae", "value_spearman", "agreement",
                 "action_distance"]


def _method_rows(summary: dict) -> list[dict]:
    own = "abc" if summary["mode"] == "imitation" else "aoc"
    flat = {k: v for k, v in summary.items() if not isinstance(v, (dict, list))}
    rows = [{"method": own, **flat}]
    for method, rec in summary["baselines"].items():
        rows.append({"method": method, **rec})
    return rows


def _ope_rows(summary: dict) -> list[dict]:
    """One row per policy: each estimator's estimate [low, high] (or why the log cannot
    support it), the ESS, the share of its episodes the log follows to their end, and the
    verdict against the logged behaviour."""
    def row(name, rec):
        support = rec.get("support") or {}
        return {"policy": name, "ess": rec["ess"],
                **{k: cell(v) for k, v in (rec["policy_value"] or {}).items()},
                "reached": support.get("reached")}

    rows = [row("aoc", summary)]
    for name, rec in summary["baselines"].items():
        if "policy_value" in rec:
            rows.append(row(name, rec))
    own = summary["behaviour_value"]
    rows.append({"policy": "behaviour", "mean_return": cell(own),
                 **({"fqe": f"{own['fqe']:.4f}"} if own.get("fqe") is not None else {})})
    return rows


def write_evaluation(summary: dict, fmt: str) -> None:
    """Print an evaluation: JSON / JSONL whole, one CSV row per method, or tables (the run, the
    methods against the log, the what-if, the OPE, the confusion and calibration)."""
    if fmt in ("json", "jsonl"):
        write_object(summary, fmt)
        return
    columns = IMITATION_COLUMNS if summary["mode"] == "imitation" else VALUE_COLUMNS
    rows = _method_rows(summary)
    present = [c for c in columns if any(r.get(c) is not None for r in rows)]
    if fmt == "csv":
        extra = ["steps", "extrapolating_share", "heterogeneity_share"]
        for r in rows[1:]:
            for c in extra:
                r[c] = rows[0][c]
        write_records(rows, "csv", columns=present + extra)
        return
    head = {k: summary[k] for k in ("mode", "corpus", "model", "data", "own_episode_left_out",
                                    "steps", "episodes", "extrapolating_share",
                                    "heterogeneity_share", "support_max", "search", "seconds",
                                    "steps_per_second")}
    res = summary["residual"]
    head["residual p50 / p90 / p99"] = f"{res['p50']:.4g} / {res['p90']:.4g} / {res['p99']:.4g}"
    head["typical residual"] = res["typical"]
    if summary.get("value_target"):
        head["value target (value_r2's)"] = summary["value_target"]
    write_object(head, "table", title=f"aoc evaluate {summary['corpus']} on {summary['data']}")
    write_records(rows, "table", columns=present, title="decisions against the log")
    if "what_if" in summary:
        w = summary["what_if"]
        head = {"without": f"{w['without']['label']} ({w['without']['rows']} rows, "
                           f"{w['without']['episodes']} episodes)",
                "steps": w["steps"], "decisions flipped": w["flipped"],
                "flip share": w["flip_share"],
                "steps whose subset lost a row": w["support_removed_steps"],
                "residual change (mean)": w["residual_change"]["mean"]}
        for key in ("value_change", "score_change"):
            if key in w:
                head[key.replace("_", " ") + " (mean / mean abs)"] = \
                    f"{w[key]['mean']:.4g} / {w[key]['mean_abs']:.4g}"
        head.update({f"{k} after": v for k, v in w["after"].items()})
        write_object(head, "table", title="what if")
    if "policy_value" in summary:
        ope = summary["ope"]
        fit = ope.get("propensity_model")
        model = "" if not fit else (f"; held-out log-loss {fit['log_loss']:.4g} (action "
                                    f"frequencies: {fit['log_loss_frequencies']:.4g}), "
                                    f"calibration error {fit['ece']:.3g}")
        write_records(_ope_rows(summary), "table",
                      title=f"policy value from the log alone (propensities: "
                            f"{ope['propensity']}{model})")
        verdicts = [{"policy": "aoc", "verdict": summary.get("verdict")}] + [
            {"policy": name, "verdict": rec.get("verdict")}
            for name, rec in summary["baselines"].items() if rec.get("verdict")]
        write_records(verdicts, "table", title="better than the logged behaviour? "
                                              "(the paired difference of the values)")
    if "confusion" in summary:
        n = len(summary["confusion"])
        write_records([{"logged": i, **{f"decided {j}": summary["confusion"][i][j]
                                        for j in range(n)}} for i in range(n)], "table",
                      title="confusion (steps)")
        write_records([b for b in summary["calibration"] if b["steps"]], "table",
                      title="calibration (score of action 1, or the top score)")
