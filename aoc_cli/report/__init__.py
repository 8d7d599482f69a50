"""Output for people and pipes: tables, JSON, JSONL and CSV writers, progress bars, plots."""

from aoc_cli.report.output import (
    FORMATS,
    ProgressBar,
    console,
    message,
    progress,
    resolve_format,
    to_jsonable,
    write_object,
    write_records,
)

__all__ = [
    "FORMATS",
    "ProgressBar",
    "console",
    "message",
    "progress",
    "resolve_format",
    "to_jsonable",
    "write_object",
    "write_records",
]
