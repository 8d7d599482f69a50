"""``aoc info NAME`` (one corpus in detail) and ``aoc ls`` (every corpus of the store)."""

from __future__ import annotations

import typer

from aoc_cli.cli.common import CorpusArgument, FormatOption, get_store


def register(app: typer.Typer) -> None:
    @app.command("info")
    def info(
        name: CorpusArgument,
        fmt: FormatOption = None,
    ) -> None:
        """Rows, episodes, spaces, returns, tags and what has been built from corpus NAME."""
        from aoc_cli.report.output import resolve_format, write_object, write_records
        from aoc_cli.store import summarize
        from aoc_cli.store.summary import space_text

        resolved = resolve_format(fmt)
        summary = summarize(get_store().corpus(name))
        if resolved != "table":
            write_object(summary, resolved)
            return
        brief = {k: v for k, v in summary.items()
                 if k not in ("tags", "built", "sources", "observation_space", "action_space")}
        brief["observation_space"] = space_text(summary["observation_space"])
        brief["action_space"] = space_text(summary["action_space"])
        brief["sources"] = "; ".join(_source_text(s) for s in summary["sources"])
        write_object(brief, "table", title=f"corpus {name}")
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
        from aoc_cli.report.output import message, write_records
        from aoc_cli.store import list_corpora

        store = get_store()
        records = list_corpora(store)
        if not records:
            message(f"no corpora in {store.root}: create one with `aoc ingest` or `aoc collect`")
        write_records(records, fmt, columns=["name", "rows", "episodes", "observation", "action",
                                             "has_rewards", "models", "status"],
                      title=str(store.root))


def _source_text(source: dict) -> str:
    """One line for a corpus source: the file an ingest read, or the task a collect ran."""
    if source.get("kind") == "collect":
        size = (f"{source['steps']} steps" if source.get("steps") is not None
                else f"{source.get('episodes')} episodes")
        return (f"collect {source.get('task', '?')} (seed {source.get('seed', '?')}, {size}; "
                f"{', '.join(source.get('policies') or [])})")
    return f"{source.get('format', '?')} {source.get('path', '?')}".strip()
