"""What every command module shares: global state, the typed options declared once, the
choices as enums (``--help`` lists them, shell completion offers them), flag parsing.

A command declares a shared option by its alias and its default, e.g.
``fmt: FormatOption = None``, ``seed: SeedOption = 0``; the flag's name and help text are the
same in every command. An option that mirrors a setting of a config dataclass takes its help,
range, choices and default from the field (:mod:`aoc_cli.cli.fields`). A command that decides
takes every controller setting at once: :func:`deciding`.
"""

from __future__ import annotations

import functools
import inspect
from dataclasses import dataclass, fields
from enum import Enum
from pathlib import Path
from typing import Annotated, Callable, List, Optional, get_type_hints

import typer

from aoc_cli.belief.config import BeliefConfig
from aoc_cli.cli.fields import MODEL, choices_of, from_field
from aoc_cli.control.config import ControllerConfig
from aoc_cli.errors import AocError
from aoc_cli.index.search.config import IndexConfig


@dataclass
class State:
    """Global options, set by the app callback before any command runs."""

    store: Optional[Path] = None


state = State()


# -- choices (str enums: a member compares equal to its value) -----------------------------
class OutputFormat(str, Enum):
    """``--format``: how data is printed on stdout."""

    table = "table"
    json = "json"
    jsonl = "jsonl"
    csv = "csv"


class PolicyName(str, Enum):
    """``--policy``: the AOC controller or a baseline (:mod:`aoc_cli.baselines`)."""

    aoc = "aoc"
    zero = "zero"
    random = "random"
    nn1 = "1nn"
    knn = "knn"
    nn1_belief = "1nn-belief"
    knn_belief = "knn-belief"
    bc = "bc"
    td3bc = "td3bc"
    cql = "cql"
    bcq = "bcq"
    mpc = "mpc"


#: The choices of a setting, from its field (``--help`` lists them).
SamplerName = choices_of(ControllerConfig, "sampler")
DoNoHarm = choices_of(ControllerConfig, "do_no_harm")
IndexKind = choices_of(IndexConfig, "kind")
BeliefMode = choices_of(BeliefConfig, "mode")
BeliefKind = choices_of(BeliefConfig, "belief")
ClassWeight = choices_of(BeliefConfig, "class_weight")
Device = choices_of(BeliefConfig, "device")


class StepCandidates(str, Enum):
    """``aoc index --candidates``: where step 1 takes its candidate rows
    (:func:`aoc_cli.index.model_k`)."""

    auto = "auto"
    nearest = "nearest"
    per_action = "per_action"


def choice(value: Enum | str | None) -> str | None:
    """The plain string of an enum choice (None stays None)."""
    return value.value if isinstance(value, Enum) else value


# -- the controller's settings, every one, on every command that decides ------------------
#: The option of each ControllerConfig field: None unless given (then: the model's, else the
#: field's default), flag, help, range and choices from the field (``-K`` for candidates).
_TYPES = {**get_type_hints(ControllerConfig), "sampler": SamplerName,
          "do_no_harm": DoNoHarm}
CONTROLLER_OPTIONS = {
    item.name: Annotated[
        Optional[_TYPES[item.name]],
        from_field(ControllerConfig, item.name,
                   *(("--candidates", "-K") if item.name == "candidates" else ()),
                   given=MODEL, annotated=True)]
    for item in fields(ControllerConfig)}


def deciding(command: Callable) -> Callable:
    """A command that decides, given every controller setting as an option: the command
    declares a parameter ``controller`` where the options go (in ``--help``'s order) and
    receives there {field: value, None where not given}, for the API's ``controller=``.
    ``tests/cli/test_option_help.py`` checks every deciding command against the fields."""
    params = [p.replace(kind=inspect.Parameter.KEYWORD_ONLY)
              for p in inspect.signature(command, eval_str=True).parameters.values()]
    cut = [p.name for p in params].index("controller")
    options = [inspect.Parameter(name, inspect.Parameter.KEYWORD_ONLY, default=None,
                                 annotation=annotation)
               for name, annotation in CONTROLLER_OPTIONS.items()]
    params[cut:cut + 1] = options

    @functools.wraps(command)
    def run(**kwargs):
        given = {name: choice(kwargs.pop(name)) for name in CONTROLLER_OPTIONS}
        return command(**kwargs, controller=given)

    run.__signature__ = inspect.Signature(params)
    run.__annotations__ = {p.name: p.annotation for p in params}
    del run.__wrapped__  # typer reads the signature above, not the command's
    return run


# -- arguments and options shared by several commands --------------------------------------
CorpusArgument = Annotated[str, typer.Argument(help="Corpus name.", show_default=False)]

FormatOption = Annotated[Optional[OutputFormat], typer.Option(
    "--format", "-f", case_sensitive=False,
    help="Output format (default: table on a terminal, json in a pipe).")]

ModelOption = Annotated[Optional[str], typer.Option(
    "--model", help="Model id (models/<ID>/ of the corpus; default: 'default', else the "
                    "latest trained).")]

IndexOption = Annotated[str, typer.Option(
    "--index", "--index-id", help="Index id: 'default' (every row once) or a derived index "
                                  "(re-sampled or sub-sampled rows).")]

PolicyOption = Annotated[PolicyName, typer.Option(
    "--policy", case_sensitive=False,
    help="aoc, or a baseline: " + ", ".join(p.value for p in PolicyName if p.value != "aoc")
         + " (the last three with the bench extra).")]

EpisodesOption = Annotated[Optional[int], typer.Option(
    "--episodes", "-n", help="Episodes to run (or to collect).")]

SeedOption = Annotated[int, typer.Option(
    "--seed", help="Random seed: the same seed gives the same result.")]

SelectOption = Annotated[Optional[List[str]], typer.Option(
    "--select", help="Only rows with TAG=VALUE[,VALUE] (repeatable).")]

ExcludeOption = Annotated[Optional[List[str]], typer.Option(
    "--exclude", help="No rows with TAG=VALUE[,VALUE] (repeatable).")]

WithoutOption = Annotated[Optional[List[str]], typer.Option(
    "--without", help="What if the corpus had no rows with TAG=VALUE[,VALUE] (repeatable): "
                      "decide again without them (a row mask, no retraining) and report what "
                      "changes.")]

WithoutEpisodesOption = Annotated[Optional[str], typer.Option(
    "--without-episodes", help="What if the corpus had not had these episodes: their ids "
                               "(e.g. patient ids) or numbers, comma-separated.")]

OverwriteOption = Annotated[bool, typer.Option("--overwrite", help="Replace an existing one.")]

WorkersOption = Annotated[Optional[int], typer.Option(
    "--workers", help="Split the work into Ray tasks on N workers: a local Ray with N CPUs, "
                      "or at most N at once on --ray-address (needs the ray extra).")]

RayAddressOption = Annotated[Optional[str], typer.Option(
    "--ray-address", help="Join this Ray cluster (also $RAY_ADDRESS with --workers) instead "
                          "of starting a local one.")]


# -- flag values ---------------------------------------------------------------------------
def _split(item: str, sep: str, flag: str, form: str) -> tuple[str, str]:
    key, found, value = item.rpartition(sep) if sep == ":" else item.partition(sep)
    if not found or not key.strip() or not value.strip():
        raise AocError(f"{flag} expects {form}, got {item!r}")
    return key.strip(), value.strip()


def parse_key_values(items: list[str] | None, flag: str) -> dict[str, str]:
    """``["a=b", "c=d"]`` -> ``{"a": "b", "c": "d"}``; a malformed item is an AocError."""
    return dict(_split(item, "=", flag, "KEY=VALUE") for item in items or [])


def parse_selection(items: list[str] | None, flag: str) -> dict[str, list[str]]:
    """``["policy=pi1,pi3", "system=normal"]`` -> ``{"policy": ["pi1", "pi3"], ...}``."""
    out: dict[str, list[str]] = {}
    for item in items or []:
        tag, values = _split(item, "=", flag, "TAG=VALUE[,VALUE...]")
        out.setdefault(tag, []).extend(v.strip() for v in values.split(",") if v.strip())
    return out


def parse_episodes(text: str | None) -> list[str] | None:
    """``--without-episodes "p1, p7"`` -> ``["p1", "p7"]``; an empty list is an AocError."""
    if text is None:
        return None
    episodes = [x.strip() for x in text.split(",") if x.strip()]
    if not episodes:
        raise AocError("--without-episodes expects ID[,ID...], got an empty list")
    return episodes


def parse_rates(items: list[str] | None, flag: str) -> dict[str, float]:
    """``["policy=pi1:4"]`` -> ``{"policy=pi1": 4.0}``."""
    out = {}
    for item in items or []:
        form = "TAG=VALUE:RATE (e.g. policy=pi1:4)"
        key, rate = _split(item, ":", flag, form)
        try:
            out[key] = float(rate)
        except ValueError:
            raise AocError(f"{flag} expects {form}, got {item!r}") from None
        if "=" not in key:
            raise AocError(f"{flag} expects {form}, got {item!r}")
    return out
