"""Every option that mirrors a setting of a config dataclass takes its help, range, choices and
default from the field (aoc_cli/cli/fields.py), so ``aoc X --help`` cannot drift from the
library's settings; a bad value still fails as one line naming the flag, exit code 2."""

from __future__ import annotations

import dataclasses
import re
from enum import Enum

import pytest
import typer.main
from typer.core import TyperOption

from aoc_cli.belief.config import BeliefConfig
from aoc_cli.cli.app import app
from aoc_cli.cli.errors import flag
from aoc_cli.control.config import ControllerConfig
from aoc_cli.ope.evaluate_block import OPESettings
from aoc_cli.index.search.config import IndexConfig
from aoc_cli.settings import param_name

#: The settings each command offers as options.
MIRRORS = {"train": [BeliefConfig], "index": [IndexConfig], "rollout": [ControllerConfig],
           "explain": [ControllerConfig], "evaluate": [ControllerConfig, OPESettings],
           "bench": [ControllerConfig]}
#: BeliefConfig's settings that aoc train does not offer (the library's only).
NOT_OFFERED = {"min_delta", "belief_activation"}


def _options(command: str) -> dict[str, TyperOption]:
    group = typer.main.get_command(app)
    return {opt: p for p in group.commands[command].params if isinstance(p, TyperOption)
            for opt in p.opts}


def mirrored(command: str) -> list[tuple[dataclasses.Field, TyperOption]]:
    options = _options(command)
    return [(item, options[flag(param_name(item))]) for cls in MIRRORS[command]
            for item in dataclasses.fields(cls) if flag(param_name(item)) in options]


def _shown(item: dataclasses.Field) -> str:
    """The field's default as --help must show it (what None means, for None)."""
    if item.default is None:
        return item.metadata["none"]
    if isinstance(item.default, tuple):
        return ",".join(item.default)
    return str(item.default)


@pytest.mark.parametrize("command", sorted(MIRRORS))
def test_every_option_that_mirrors_a_setting_shows_its_help_range_and_default(command):
    pairs = mirrored(command)
    assert pairs, command
    for item, option in pairs:
        where = f"aoc {command} {option.opts[0]}"
        assert item.metadata["help"] in option.help, where
        bounds = item.metadata.get("bounds")
        if bounds:
            assert f"Range: {bounds.removeprefix('in ')}." in option.help, where
        if "choices" in item.metadata:
            choices = option.type_descriptor.annotation
            assert tuple(c.value for c in choices) == item.metadata["choices"], where
        if option.default is None:  # not given: the model's setting, a rule, or the field's
            assert isinstance(option.show_default, str), where
            assert _shown(item) in option.show_default, where
        else:
            default = option.default.value if isinstance(option.default, Enum) \
                else option.default
            assert default == item.default and option.show_default is not False, where


#: The commands that decide: each takes every controller setting (aoc_cli.cli.common.deciding).
DECIDING = ("rollout", "explain", "evaluate", "bench")


@pytest.mark.parametrize("command", DECIDING)
def test_every_deciding_command_offers_every_controller_setting_none_unless_given(command):
    options = _options(command)
    for item in dataclasses.fields(ControllerConfig):
        option = options.get(flag(param_name(item)))
        assert option is not None, f"aoc {command} has no {flag(param_name(item))}"
        assert option.default is None, f"aoc {command} {option.opts[0]}"  # not given: None


@pytest.mark.parametrize("command, args", [
    ("rollout", ["g", "--env", "two-gates"]), ("explain", ["g", "--data", "g"]),
    ("evaluate", ["g", "--data", "g"]), ("bench", ["two-gates"])])
def test_a_deciding_command_hands_its_entry_the_settings_given_and_none_for_the_rest(
        aoc_inproc, monkeypatch, command, args):
    import aoc_cli

    seen = {}

    def entry(*_args, controller=None, **_kwargs):
        seen.update(controller)
        raise aoc_cli.errors.AocError("stop here")

    monkeypatch.setattr(aoc_cli, command, entry)
    code, _, err = aoc_inproc(command, *args, "--residual-cap", "2", "--sampler", "bc",
                              "--ood-sigmas", "4")
    assert code == 2 and "stop here" in err
    assert seen == {**{item.name: None for item in dataclasses.fields(ControllerConfig)},
                    "residual_cap": 2.0, "sampler": "bc", "ood_sigmas": 4.0}
    assert type(seen["sampler"]) is str  # the plain value, not the enum


def test_train_offers_every_belief_setting_but_the_library_only_ones():
    offered = {item.name for item, _ in mirrored("train")}
    names = {item.name for item in dataclasses.fields(BeliefConfig)}
    assert offered == names - NOT_OFFERED


def test_help_prints_the_default_of_a_setting(aoc_inproc, monkeypatch):
    monkeypatch.setenv("COLUMNS", "200")
    code, out, _ = aoc_inproc("rollout", "--help")
    assert code == 0
    text = " ".join(out.replace("│", " ").split())
    model = "the model's (decided by aoc train from the log's evidence)"
    assert f"[default: ({model}, else 0.5)]" in text  # --epsilon
    assert f"[default: ({model}, else no cap)]" in text  # --residual-cap
    code, out, _ = aoc_inproc("train", "--help")
    assert re.search(r"--batch-size .*Mini-batch rows\. Range: >= 1\. \[default: 500\]",
                     " ".join(out.replace("│", " ").split()))


@pytest.mark.parametrize("args, line", [
    (["train", "c", "--lr", "0"], "aoc: error: --lr must be > 0, got 0.0"),
    (["train", "c", "--epochs", "0"], "aoc: error: --epochs must be >= 1, got 0"),
    (["train", "c", "--val-fraction", "1"], "aoc: error: --val-fraction must be in (0, 1), "
                                            "got 1.0"),
    (["evaluate", "c", "--data", "c", "--ope-gamma", "0"],
     "aoc: error: --ope-gamma must be in (0, 1], got 0.0"),
    (["index", "c", "--kind", "lsh"], "aoc: error: unknown --kind: 'lsh' is not one of"),
])
def test_a_bad_value_is_one_line_with_the_flag_and_exit_2(aoc_inproc, store, args, line):
    code, out, err = aoc_inproc(*args)
    assert code == 2 and out == ""
    assert len(err.strip().splitlines()) == 1 and err.startswith(line), err
