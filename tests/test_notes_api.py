"""The notes scripts (benchmarks/notes/) drive aoc through its public API.

A note imports ``aoc_cli``'s entries and the names a stage package (or a top-level module such
as ``aoc_cli.threads``) lists in its ``__all__``; a note that studies an internal (the engine's
solves, the critic alone) imports that module under a ``# internal:`` comment saying why, on the
import's line or above its block. No note edits ``sys.path`` to reach another folder.
"""

from __future__ import annotations

import ast
import importlib
from pathlib import Path

import pytest

NOTES = sorted((Path(__file__).resolve().parents[1] / "benchmarks" / "notes").glob("*.py"))


def public(module: str) -> bool:
    """``aoc_cli`` or one level below it (a stage package or a top-level module)."""
    parts = module.split(".")
    return parts[0] == "aoc_cli" and len(parts) <= 2


def explained(lines: list[str], node: ast.stmt) -> bool:
    """A ``# internal:`` comment on the import's lines or above its block of imports."""
    if any("# internal:" in lines[i] for i in range(node.lineno - 1, node.end_lineno)):
        return True
    above = node.lineno - 2
    while above >= 0 and lines[above].strip().startswith(("from ", "import ")):
        above -= 1
    return above >= 0 and lines[above].strip().startswith("# internal:")


def problems(path: Path) -> list[str]:
    source = path.read_text()
    lines = source.splitlines()
    out = []
    if "sys.path.insert" in source or "sys.path.append" in source:
        out.append(f"{path.name}: edits sys.path")
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.ImportFrom) and (node.module or "").startswith("aoc_cli"):
            module, names = node.module, [a.name for a in node.names]
        elif isinstance(node, ast.Import):
            hits = [a.name for a in node.names if a.name.startswith("aoc_cli")]
            if not hits:
                continue
            module, names = hits[0], []
        else:
            continue
        where = f"{path.name}:{node.lineno}"
        if not public(module):
            if not explained(lines, node):
                out.append(f"{where}: {module} is internal, with no `# internal:` reason")
            continue
        exported = getattr(importlib.import_module(module), "__all__", None)
        for name in names:
            if name.startswith("_") or (exported is not None and name not in exported):
                out.append(f"{where}: {module}.{name} is not in {module}.__all__")
    return out


def test_the_notes_exist():
    assert len(NOTES) >= 10


@pytest.mark.parametrize("path", NOTES, ids=lambda p: p.name)
def test_notes_use_the_public_api(path):
    assert problems(path) == []


def test_the_rule_catches_an_internal_import(tmp_path):
    bad = tmp_path / "bad.py"
    bad.write_text("import sys\nsys.path.insert(0, 'x')\n"
                   "from aoc_cli.belief.targets import value_targets\n"
                   "from aoc_cli.belief import _hidden\n"
                   "# internal: measured on purpose\nimport aoc_cli.decompose.engine as e\n")
    found = problems(bad)
    assert [p.split(": ", 1)[1] for p in found] == [
        "edits sys.path",
        "aoc_cli.belief.targets is internal, with no `# internal:` reason",
        "aoc_cli.belief._hidden is not in aoc_cli.belief.__all__"]
