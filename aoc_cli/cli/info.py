"""``aoc info NAME`` (one corpus in detail) and ``aoc ls`` (every corpus of the store)."""

from __future__ import annotations

import typer

import aoc_cli
from aoc_cli.cli.common import CorpusArgument, FormatOption, state
from aoc_cli.cli.output import message, resolve_format, write_object, write_records
from aoc_cli.formats import bins as dose_bins
from aoc_cli.store.summary import space_text


def register(app: typer.Typer) -> None:
    @app.command("info")
    def info(
        name: CorpusArgument,
        fmt: FormatOption = None,
    ) -> None:
        """Rows, episodes, spaces, returns, tags and what has been built from corpus NAME."""
        resolved = resolve_format(fmt)
        summary = aoc_cli.info(name, store=state.store)
        if resolved != "table":
            write_object(summary, resolved)
            return
        brief = {k: v for k, v in summary.items()
                 if k not in ("tags", "built", "sources", "observation_space", "action_space",
                              "preprocessing", "imputed_cells")}
        brief["observation_space"] = space_text(summary["observation_space"])
        brief["action_space"] = space_text(summary["action_space"])
        brief["sources"] = "; ".join(_source_text(s) for s in summary["sources"])
        if summary.get("preprocessing"):
            brief["preprocessing"] = preprocessing_text(summary["preprocessing"])
        write_object(brief, "table", title=f"corpus {name}")
        if summary.get("imputed_cells"):
            write_records(imputed_rows(summary["imputed_cells"], summary["rows"]), "table",
                          title="imputed cells")
        tag_rows = [{"tag": t, "label": label, "rows": n}
                    for t, counts in summary["tags"].items() for label, n in counts.items()]
        if tag_rows:
            write_records(tag_rows, "table", title="tags")
        if summary["built"]:
            write_records([{**m, "files": ", ".join(m["files"])} for m in summary["built"]],
                          "table", title="built from this corpus")

    @app.command("ls")
    def ls(fmt: FormatOption = None) -> None:
        """List the corpora of the store."""
        root, records = aoc_cli.corpora(store=state.store)
        if not records:
            message(f"no corpora in {root}: create one with `aoc ingest` or `aoc collect`")
        write_records(records, fmt, columns=["name", "rows", "episodes", "observation", "action",
                                             "has_rewards", "models", "status"],
                      title=str(root))


def imputed_rows(cells: dict, rows: int) -> list[dict]:
    """One row per imputed column: cells filled and their share of the column."""
    return [{"column": c, "imputed": n, "share": f"{100 * n / max(rows, 1):.1f}%"}
            for c, n in cells.items()]


def preprocessing_text(pre: dict) -> str:
    """One line for what was fitted while reading: rule, bins, outcome, split."""
    parts = []
    if "impute" in pre:
        imp = pre["impute"]
        parts.append(f"impute {imp['rule']}" + (" + measured features" if imp.get("mask")
                                                  else "")
                     + (f" (like {pre['like']['impute']})" if "impute" in pre.get("like", {})
                        else ""))
    if "bins" in pre:
        b = pre["bins"]
        parts.append("dose bins " + dose_bins.describe(dose_bins.asked_of(b)))
    if "outcome" in pre:
        o = pre["outcome"]
        parts.append(f"outcome {o['column']} (" + ",".join(f"{k}={v:g}" for k, v in
                                                          o["rewards"].items()) + ")")
    if "split" in pre:
        sp = pre["split"]
        parts.append(f"{sp['part']} part of {sp['corpus']!r} split")
    return "; ".join(parts)


def _source_text(source: dict) -> str:
    """One line for a corpus source: the file an ingest read, or the task a collect ran."""
    if source.get("kind") == "collect":
        size = (f"{source['steps']} steps" if source.get("steps") is not None
                else f"{source.get('episodes')} episodes")
        return (f"collect {source.get('task', '?')} (seed {source.get('seed', '?')}, {size}; "
                f"{', '.join(source.get('policies') or [])})")
    return f"{source.get('format', '?')} {source.get('path', '?')}".strip()
