"""The options that mirror a setting of a config dataclass, built from the dataclass's field
(:func:`aoc_cli.settings.setting`): the flag, the help, the range, the choices and the default
shown all come from there, so ``--help`` cannot drift from the library's settings.

>>> epsilon: Optional[float] = from_field(ControllerConfig, "epsilon", given=MODEL)
>>> batch_size: int = from_field(BeliefConfig, "batch_size")

``given``: the option's value is None unless given, and then means this (``MODEL``: the
setting saved with the model, else the field's default; ``EVIDENCE``: decided by ``aoc train``
from the log's evidence); without it the option's default is the field's.
"""

from __future__ import annotations

from dataclasses import MISSING, Field, fields
from enum import Enum

import typer

from aoc_cli.cli.errors import flag
from aoc_cli.settings import bounds_text, param_name

#: ``given=EVIDENCE``: None means the value ``aoc train`` decides from the log's evidence
#: (aoc_cli.training.evidence), else the field's default.
EVIDENCE = "decided from the log's evidence where a rule applies (docs/design.md), else {default}"
#: ``given=MODEL``: None means the controller setting saved with the model (decided by ``aoc
#: train`` from the log's evidence), else the field's default.
MODEL = "the model's (decided by aoc train from the log's evidence), else {default}"


def field_of(cls, name: str) -> Field:
    """The field ``name`` of settings dataclass ``cls``."""
    for item in fields(cls):
        if item.name == name:
            return item
    raise KeyError(f"{cls.__name__} has no setting {name!r}")


def default_text(item: Field) -> str:
    """The field's default as ``--help`` shows it (what None means, for a None default)."""
    if item.default is None:
        return item.metadata.get("none", "none")
    if item.default is MISSING:
        return "required"
    if isinstance(item.default, tuple):
        return ",".join(str(x) for x in item.default)
    return str(item.default)


def help_of(cls, name: str, more: str = "") -> str:
    """The field's help, its range and ``more``."""
    item = field_of(cls, name)
    text = item.metadata["help"]
    bounds = item.metadata.get("bounds")
    if bounds is not None:
        text += f" Range: {bounds_text(bounds).removeprefix('in ')}."
    if more:
        text += " " + more
    return text


def choices_of(cls, name: str) -> type[Enum]:
    """The field's choices as a str enum (``--help`` lists them, shell completion offers
    them; a member compares equal to its value)."""
    values = field_of(cls, name).metadata["choices"]
    return Enum(f"{cls.__name__}_{name}", [(v, v) for v in values], type=str)


def from_field(cls, name: str, *flags: str, given: str | None = None, more: str = "",
               annotated: bool = False, **options) -> typer.models.OptionInfo:
    """The typer option of setting ``name`` of ``cls``: ``flags`` (default: the setting's
    flag, as errors show it), the help of :func:`help_of`, ``case_sensitive=False`` for a
    field with choices. Its default: None with ``given`` (shown as ``given`` with the field's
    default as ``{default}``), else the field's (typer shows it). ``annotated``: for
    ``Annotated[T, from_field(...)]`` (the default is then written after the parameter)."""
    item = field_of(cls, name)
    if given is None and item.default is None:  # None is the field's own: say what it means
        given = "{default}"
    decls = flags or (flag(param_name(item)),)
    if "choices" in item.metadata:
        options.setdefault("case_sensitive", False)
    if given is not None:  # typer shows it as "[default: (the task's, else 0.5)]"
        options["show_default"] = given.format(default=default_text(item))
    text = help_of(cls, name, more)
    if annotated:
        return typer.Option(*decls, help=text, **options)
    default = None if given is not None else item.default
    return typer.Option(default, *decls, help=text, **options)
