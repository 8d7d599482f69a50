"""What every command module shares: global state, the --format option, tag parsing."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Optional

import typer

from aoc_cli.errors import AocError


@dataclass
class State:
    """Global options, set by the app callback before any command runs."""

    store: Optional[Path] = None
    debug: bool = False


state = State()

FormatOption = typer.Option(
    None,
    "--format",
    "-f",
    help="Output format: table|json|jsonl|csv (default: table on a terminal, json in a pipe).",
)


def get_store():
    """The corpus store selected by --store, AOC_STORE or ./corpora."""
    from aoc_cli.store import Store

    return Store.open(state.store)


def parse_key_values(items: list[str] | None, flag: str) -> dict[str, str]:
    """``["a=b", "c=d"]`` -> ``{"a": "b", "c": "d"}``; a malformed item is an AocError."""
    out: dict[str, str] = {}
    for item in items or []:
        key, sep, value = item.partition("=")
        if not sep or not key or not value:
            raise AocError(f"{flag} expects KEY=VALUE, got {item!r}")
        out[key.strip()] = value.strip()
    return out


def parse_rates(items: list[str] | None, flag: str) -> dict[str, float]:
    """``["policy=pi1:4"]`` -> ``{"policy=pi1": 4.0}``."""
    out = {}
    for item in items or []:
        key, sep, rate = item.rpartition(":")
        try:
            value = float(rate)
        except ValueError:
            value = None
        if not sep or "=" not in key or value is None:
            raise AocError(f"{flag} expects TAG=VALUE:RATE (e.g. policy=pi1:4), got {item!r}")
        out[key] = value
    return out
