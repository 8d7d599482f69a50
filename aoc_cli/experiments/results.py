"""Bench outputs: results.csv (one row per method x setting x seed), summary.json, summary.md.

A result row has the columns of :data:`COLUMNS` (empty where a metric does not apply). The
summary groups rows by (task, method, setting): each metric's ``mean`` is the mean of the
per-seed values and its ``std`` the standard deviation across seeds (with one seed: the std of
that seed's episodes, for the return, marked ``std_of = "episodes"``).
"""

from __future__ import annotations

import csv
import io
import json
import math
from pathlib import Path

import numpy as np

from aoc_cli.report import to_jsonable
from aoc_cli.store import atomic_path

COLUMNS = ["experiment", "task", "method", "setting", "seed", "status", "episodes",
           "return_mean", "return_std", "success_rate", "upper_gate", "lower_gate",
           "ood_delay", "ood_flagged", "ood_false_flags", "mean_residual", "seconds_per_step",
           "note"]
METRICS = ["return_mean", "success_rate", "upper_gate", "lower_gate", "ood_delay",
           "ood_flagged", "ood_false_flags", "mean_residual", "seconds_per_step"]


def result_row(experiment: str, task: str, method: str, setting: str, seed: int, **values) -> dict:
    """One results.csv row (missing metrics are None)."""
    row = {c: None for c in COLUMNS}
    row.update(experiment=experiment, task=task, method=method, setting=setting, seed=int(seed),
               status="ok")
    row.update(values)
    return row


def _finite(values) -> list[float]:
    out = []
    for v in values:
        if v is None or v == "":
            continue
        v = float(v)
        if math.isfinite(v):
            out.append(v)
    return out


def summarize_rows(rows: list[dict], paper=None) -> list[dict]:
    """One record per (task, method, setting), in first-seen order (module docstring).

    ``paper(row) -> figure or None`` gives the paper's figure of a group.
    """
    groups: dict[tuple, list[dict]] = {}
    for r in rows:
        groups.setdefault((r["task"], r["method"], r["setting"]), []).append(r)
    out = []
    for (task, method, setting), members in groups.items():
        ok = [m for m in members if m["status"] == "ok"]
        rec = {"experiment": members[0]["experiment"], "task": task, "method": method,
               "setting": setting, "seeds": len(ok),
               "status": "ok" if ok else members[0]["status"],
               "note": "; ".join(sorted({str(m["note"]) for m in members if m.get("note")}))}
        for metric in METRICS:
            vals = _finite(m[metric] for m in ok)
            if not vals:
                rec[metric] = rec[f"{metric}_std"] = None
                continue
            rec[metric] = float(np.mean(vals))
            rec[f"{metric}_std"] = float(np.std(vals)) if len(vals) > 1 else None
        rec["std_of"] = "seeds" if len(ok) > 1 else "episodes"
        if len(ok) == 1:
            rec["return_mean_std"] = ok[0]["return_std"]
        figure = paper(members[0]) if paper is not None else None
        rec["paper"] = None if figure is None else (list(figure) if isinstance(figure, tuple)
                                                    else figure)
        out.append(rec)
    return out


def write_csv(path: Path, rows: list[dict]) -> None:
    buf = io.StringIO()
    writer = csv.DictWriter(buf, fieldnames=COLUMNS, lineterminator="\n")
    writer.writeheader()
    for r in rows:
        writer.writerow({c: _csv_cell(r.get(c)) for c in COLUMNS})
    with atomic_path(path, suffix=".csv") as tmp:
        Path(tmp).write_text(buf.getvalue())


def write_rows_csv(path: Path, rows: list[dict]) -> None:
    """``rows`` as a CSV whose columns are every key of the rows, in first-seen order (the
    experiments whose rows are not :data:`COLUMNS`: ward, icu-sepsis); written atomically."""
    columns = list(dict.fromkeys(k for r in rows for k in r)) or ["method"]
    buf = io.StringIO()
    writer = csv.DictWriter(buf, fieldnames=columns, lineterminator="\n")
    writer.writeheader()
    writer.writerows(rows)
    with atomic_path(path, suffix=".csv") as tmp:
        Path(tmp).write_text(buf.getvalue())


def _csv_cell(v):
    if v is None:
        return ""
    if isinstance(v, float):
        return repr(v) if math.isfinite(v) else ""
    return v


def read_csv(path: Path) -> list[dict]:
    """results.csv back as dicts (numbers as floats, empty cells as None)."""
    out = []
    with open(path, newline="") as f:
        for r in csv.DictReader(f):
            row = {}
            for k, v in r.items():
                if v == "":
                    row[k] = None
                elif k in METRICS or k in ("return_std", "episodes", "seed"):
                    row[k] = float(v) if k not in ("episodes", "seed") else int(float(v))
                else:
                    row[k] = v
            out.append(row)
    return out


def write_json(path: Path, obj) -> None:
    with atomic_path(path, suffix=".json") as tmp:
        Path(tmp).write_text(json.dumps(to_jsonable(obj), indent=2) + "\n")


def _pm(mean, std, digits: int = 4) -> str:
    if mean is None:
        return "–"
    s = f"{mean:.{digits}g}"
    if std is not None:
        s += f" ± {std:.3g}"
    return s


def _paper_cell(figure) -> str:
    if figure is None:
        return ""
    if isinstance(figure, (list, tuple)):
        parts = [f"{x:.4g}" if isinstance(x, float) else str(x) for x in figure]
        return " / ".join(parts) if len(figure) > 2 else f"{parts[0]} ± {parts[1]}"
    return f"{figure:.4g}"


def summary_markdown(title: str, summary: list[dict], metrics: list[tuple[str, str]],
                     header: str = "", paper_label: str = "paper") -> str:
    """A markdown table per task: method | setting | seeds | metrics (mean ± std) | paper."""
    lines = [f"# {title}", ""]
    if header:
        lines += [header, ""]
    tasks = list(dict.fromkeys(r["task"] for r in summary))
    for task in tasks:
        lines += [f"## {task}", ""]
        cols = ["method", "setting", "seeds"] + [label for _m, label in metrics] + [paper_label]
        lines.append("| " + " | ".join(cols) + " |")
        lines.append("|" + "|".join(["---"] * len(cols)) + "|")
        for r in summary:
            if r["task"] != task:
                continue
            if r["status"] != "ok":
                cells = [r["method"], r["setting"], "0"] + \
                    [f"{r['status']}: {r['note']}"] + [""] * (len(metrics) - 1) + [""]
            else:
                cells = [r["method"], r["setting"], str(r["seeds"])]
                cells += [_pm(r.get(m), r.get(f"{m}_std")) for m, _l in metrics]
                cells.append(_paper_cell(r.get("paper")))
            lines.append("| " + " | ".join(str(c) for c in cells) + " |")
        lines.append("")
    return "\n".join(lines)


def write_outputs(out: Path, experiment: str, rows: list[dict], summary: list[dict],
                  markdown: str, extra: dict | None = None) -> None:
    """results.csv, summary.json and summary.md in ``out`` (each written atomically)."""
    out.mkdir(parents=True, exist_ok=True)
    write_csv(out / "results.csv", rows)
    write_json(out / "summary.json", {"experiment": experiment, "summary": summary,
                                      **(extra or {})})
    with atomic_path(out / "summary.md", suffix=".md") as tmp:
        Path(tmp).write_text(markdown + "\n")
