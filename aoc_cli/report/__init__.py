"""What the library writes for people: the HTML decision and overview pages, plots, and
values made JSON-ready (``to_jsonable``). The command line's tables, JSON, JSONL and CSV
writers and progress bars are its own (:mod:`aoc_cli.cli.output`)."""

from aoc_cli.report.jsonable import to_jsonable

__all__ = ["to_jsonable"]
