"""docs/reference/cli.md and docs/reference/api.md are generated from the code
(scripts/gen_reference.py): this fails when either differs from what the code gives now, and
says the command that regenerates them. The pages do not depend on the terminal's width."""

import importlib.util
import os
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def gen():
    spec = importlib.util.spec_from_file_location("gen_reference", ROOT / "scripts" / "gen_reference.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_the_references_match_the_code(gen):
    stale = gen.stale()
    assert not stale, (", ".join(str(p.relative_to(ROOT)) for p in stale)
                       + f" differ from the code: run `{gen.COMMAND}` and commit the result")


def test_the_cli_reference_names_every_command_and_option(gen):
    import typer

    from aoc_cli.cli.app import app

    text = (ROOT / "docs" / "reference" / "cli.md").read_text()
    group = typer.main.get_command(app)
    for name in group.list_commands(None):
        command = group.get_command(None, name)
        assert f"## aoc {name}\n" in text, name
        for param in command.params:
            if param.param_type_name == "option" and not param.hidden:
                assert f"`{param.opts[0]}" in text or f", {param.opts[0]}" in text, (name, param.opts)


def test_the_api_reference_names_every_public_entry(gen):
    import aoc_cli

    text = (ROOT / "docs" / "reference" / "api.md").read_text()
    for name in aoc_cli.API:
        assert f"### aoc_cli.{name}\n" in text, name


def test_the_pages_do_not_depend_on_the_terminal_width(gen, monkeypatch):
    pages = {}
    for columns in ("40", "250"):
        monkeypatch.setenv("COLUMNS", columns)
        pages[columns] = gen.cli_page()
    assert pages["40"] == pages["250"]
