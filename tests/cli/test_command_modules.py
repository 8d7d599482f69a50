"""Every command module parses its options, makes one call of the library's API
(aoc_cli/api/, reached as ``aoc_cli.<entry>``: the package loads an entry on first use, so
``aoc --help`` and bad input import no torch) and prints; it imports nothing inside its
functions."""

from __future__ import annotations

import ast
from pathlib import Path

import pytest
import typer.main

import aoc_cli
from aoc_cli.cli.app import COMMANDS, app

CLI = Path(__file__).resolve().parents[2] / "aoc_cli" / "cli"
#: The command modules' names, as the app imports them.
NAMES = [module.__name__.rsplit(".", 1)[1] for module in COMMANDS]


def _inner_imports(tree: ast.AST) -> list[ast.AST]:
    out = []
    for fn in ast.walk(tree):
        if isinstance(fn, (ast.FunctionDef, ast.AsyncFunctionDef)):
            out += [n for n in ast.walk(fn) if isinstance(n, (ast.Import, ast.ImportFrom))]
    return list({id(n): n for n in out}.values())


def _commands(tree: ast.AST) -> list[ast.FunctionDef]:
    """The functions registered as commands (decorated ``@app.command``, or passed to it)."""
    named = {c.args[0].id for c in ast.walk(tree) if isinstance(c, ast.Call)
             and isinstance(c.func, ast.Call) and ast.unparse(c.func.func) == "app.command"
             and c.args and isinstance(c.args[0], ast.Name)}
    return [f for f in ast.walk(tree) if isinstance(f, ast.FunctionDef) and (
        f.name in named or any("app.command" in ast.unparse(d) for d in f.decorator_list))]


def test_every_command_module_is_imported_and_registered_by_name():
    """The app imports each command module by name (no silent skip of a missing one)."""
    modules = sorted(p.stem for p in CLI.glob("*.py") if "def register(" in p.read_text())
    assert sorted(NAMES) == modules
    assert set(typer.main.get_command(app).commands) >= set(NAMES)


@pytest.mark.parametrize("command", NAMES)
def test_a_command_makes_one_api_call_and_imports_nothing_inside_its_functions(command):
    tree = ast.parse((CLI / f"{command}.py").read_text())
    inner = _inner_imports(tree)
    assert not inner, [ast.unparse(n) for n in inner]
    commands = _commands(tree)
    assert commands
    for fn in commands:
        calls = {ast.unparse(c.func) for c in ast.walk(fn) if isinstance(c, ast.Call)
                 and ast.unparse(c.func).split(".")[0] in ("aoc_cli", "api")}
        assert calls <= {f"aoc_cli.{entry}" for entry in aoc_cli.API}, (fn.name, calls)
        assert len(calls) == 1 or calls == {"aoc_cli.tasks", "aoc_cli.collect"}, (fn.name, calls)


def test_the_shared_modules_of_the_command_line_import_nothing_inside_functions():
    for name in ("common.py", "fields.py", "errors.py"):
        assert not _inner_imports(ast.parse((CLI / name).read_text())), name
