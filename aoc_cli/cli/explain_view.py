"""What ``aoc explain`` prints of explained decisions (:func:`aoc_cli.api.explain`'s
records): JSON, JSONL, CSV with one row per supporting row, or tables."""

from __future__ import annotations

import numpy as np

from aoc_cli.cli.output import console, write_object, write_records


def _flat(rec: dict) -> list[dict]:
    """One row per supporting example, with the decision's figures repeated (for CSV)."""
    base = {k: rec.get(k) for k in ("query", "role", "data", "episode", "step", "action",
                                     "action_label", "value", "residual", "support_episodes")
            if k in rec}
    if "what_if" in rec:
        base.update({f"what_if_{k}": rec["what_if"][k] for k in ("action", "value", "residual")})
    rows = []
    for s in rec["support"]:
        row = dict(base)
        row.update({f"support_{k}": v for k, v in s.items() if k not in ("tags", "attribution")})
        if "attribution" in s:
            row["support_projection"] = s["attribution"]["projection"]
        row.update({f"tag_{k}": v for k, v in s["tags"].items()})
        rows.append(row)
    return rows


def write_explained(records: list[dict], fmt: str) -> None:
    """Print explained decisions: JSON (one object, or ``decisions``), JSONL, CSV (one row per
    supporting row) or tables (the decision, its minimal corpus subset, warnings, the
    contrast, the what-if)."""
    if fmt == "json":
        write_object({"decisions": records}, "json") if len(records) > 1 else \
            write_object(records[0], "json")
    elif fmt == "jsonl":
        for rec in records:
            write_object(rec, "jsonl")
    elif fmt == "csv":
        write_records([row for rec in records for row in _flat(rec)], "csv")
    else:
        for rec in records:
            typical = rec.get("typical_residual")
            head = {"action": rec["action"], **({"action label": rec["action_label"]}
                                                  if "action_label" in rec else {}),
                    "value (v_hat)": rec["value"], "residual": rec["residual"],
                    "support (episodes)": rec.get("support_episodes")}
            if "rule" in rec:    # rule 7, do no harm
                head["rule"] = rec["rule"]
            if "scores" in rec:  # discrete imitation: sum over the rows of weight x label
                head["scores"] = [round(v, 4) for v in rec["scores"]]
            if typical:
                head["typical residual"] = typical
                head["residual / typical"] = rec["residual"] / typical if typical else None
            if "candidates" in rec:
                c = rec["candidates"]
                head["candidates passed"] = f"{c['passed']} of {c['count']}"
                head["best rejected v_hat"] = c["best_rejected_value"]
            for key in ("recorded_action", "logged_action"):
                if key in rec:
                    head[key.replace("_", " ")] = rec[key]
                if f"{key}_label" in rec:
                    head[f"{key.replace('_', ' ')} label"] = rec[f"{key}_label"]
            where = f"{rec['data']} " if "data" in rec else ""
            title = rec.get("role", "decision") + \
                (f" (query {rec['query']})" if "query" in rec else "") + \
                (f" ({where}episode {rec['episode']}"
                 + (f" '{rec['episode_id']}'" if rec.get("episode_id") is not None else "")
                 + f", step {rec['step']})"
                 if "episode" in rec else "")
            write_object(head, "table", title=title)
            write_records(_support_rows(rec["support"], rec["action"]), "table",
                          title="minimal corpus subset")
            for w in rec["warnings"]:
                console.print(f"[yellow]warning:[/] {w}")
            if rec.get("contrast"):
                _print_contrast(rec["contrast"])
            if "what_if" in rec:
                _print_what_if(rec["what_if"])


def _print_contrast(c: dict) -> None:
    """The best action not chosen: its figures, why it lost, its own supporting rows."""
    head = {"action": c["action"], "value (v_hat)": c["value"], "residual": c["residual"],
            "why it lost": c["why"]["text"]}
    if "score" in c:
        head["score"] = c["score"]
    write_object(head, "table", title="contrast: the best action not chosen")
    if c["support"]:
        write_records(_support_rows(c["support"], c["action"]), "table",
                      title="its supporting rows")


def _support_rows(support: list[dict], action=None) -> list[dict]:
    """The subset's rows as table records; no value column where no row has a value
    (imitation: the rows' actions are what the decision weighs); the episode's own id where
    the corpus has ids, else its number (the JSON keeps both). Discrete imitation: each
    row's label of ``action`` (the decided or contrasted one; the score of that action is
    the sum of weight x label), weights and distances to 3 significant digits (the JSON
    keeps them whole)."""
    valued = any(s["value"] is not None for s in support)
    code = int(np.asarray(action).reshape(-1)[0]) if action is not None else None
    return [{"row": s["row"],
             **({"episode_id": s["episode_id"]} if s.get("episode_id") is not None
                else {"episode": s["episode"]}),
             "step": s["step"], **s["tags"], "action": s["action"],
             **({"action label": s["action_label"]} if "action_label" in s else {}),
             **({"value": s["value"]} if valued else {}),
             **({"weight": float(f"{s['weight']:.3g}"), "label": round(s["label"][code], 3),
                 "distance": float(f"{s['distance']:.3g}")}
                if "label" in s and code is not None else
                {"weight": s["weight"], "distance": s["distance"]}),
             "episodes here": s.get("episodes_here")} for s in support]


def _print_what_if(w: dict) -> None:
    """The what-if of one decision as two tables: the decision again, its new subset."""
    head = {"without": f"{w['without']['label']} ({w['without']['rows']} rows, "
                       f"{w['without']['episodes']} episodes)",
            "action": w["action"], "action changed": w["action_changed"],
            "value (v_hat)": w["value"], "value change": w["value_change"],
            "residual": w["residual"], "residual change": w["residual_change"],
            "supporting rows removed": len(w["support_removed"]),
            "unchanged": w["unchanged"]}
    write_object(head, "table", title="what if")
    write_records(_support_rows(w["support"], w["action"]), "table",
                  title="minimal corpus subset without them")
