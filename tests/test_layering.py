"""The house reads one way (docs/design.md, "Module map"): every stage imports only the low
modules and the stages before it, and no two modules import each other, not even through an
import inside a function. Read from the source (every ``import`` statement, at the top or
inside a function; those under ``if TYPE_CHECKING:`` are annotations only and not counted)."""

from __future__ import annotations

import ast
from collections import defaultdict
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1] / "aoc_cli"

#: Modules any stage may import; each imports only the ones before it in this list.
LOW = ["lazy", "errors", "settings", "progress", "metrics", "rows", "threads", "parallel"]  # docs/design.md, "Module map"
#: The stages, in the order of the flow: each may import the low modules and the stages before it.
#: A stage is a package of aoc_cli, or a floor of one ("index.search": the arrays-only search of
#: the index room, below decompose; "index": the rest of the room, the corpus index, above belief).
STAGES = ["store", "formats", "envs", "index.search", "decompose", "belief", "index", "ope",
          "control", "training", "evaluation", "baselines", "report", "explanation",
          "experiments", "api", "cli"]


def _modules() -> dict[str, Path]:
    out = {}
    for path in sorted(ROOT.rglob("*.py")):
        parts = ("aoc_cli",) + path.relative_to(ROOT).with_suffix("").parts
        if parts[-1] == "__init__":
            parts = parts[:-1]
        out[".".join(parts)] = path
    return out


MODULES = _modules()


def _type_checking(node: ast.AST, parents: dict) -> bool:
    while node in parents:
        node = parents[node]
        if isinstance(node, ast.If) and "TYPE_CHECKING" in ast.unparse(node.test):
            return True
    return False


def _imports(module: str, path: Path) -> list[tuple[str, int]]:
    """(imported aoc_cli module, line) of every import statement of ``module``."""
    tree = ast.parse(path.read_text())
    parents = {child: node for node in ast.walk(tree) for child in ast.iter_child_nodes(node)}
    package = module if path.name == "__init__.py" else module.rsplit(".", 1)[0]
    out = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            names = [a.name for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                base = ".".join(package.split(".")[:len(package.split(".")) - node.level + 1]
                                + ([base] if base else []))
            # `from pkg import mod` imports the module pkg.mod
            names = [f"{base}.{a.name}" if f"{base}.{a.name}" in MODULES else base
                     for a in node.names]
        else:
            continue
        if _type_checking(node, parents):
            continue
        for name in names:
            if name.startswith("aoc_cli."):
                while name not in MODULES and "." in name:
                    name = name.rsplit(".", 1)[0]
                out.append((name, node.lineno))
    return out


def _unit(module: str) -> str:
    """The stage or low module a module belongs to (``aoc_cli.control.run`` -> ``control``,
    ``aoc_cli.index.search.strata`` -> ``index.search``)."""
    parts = module.split(".")
    if len(parts) > 2 and f"{parts[1]}.{parts[2]}" in STAGES:
        return f"{parts[1]}.{parts[2]}"
    return parts[1] if len(parts) > 1 else "aoc_cli"


def _allowed(unit: str) -> set[str]:
    if unit in LOW:
        return set(LOW[:LOW.index(unit) + 1])
    if unit == "aoc_cli":  # the package itself re-exports the public API
        return {"aoc_cli", "api", *LOW}
    return {unit, *LOW, *STAGES[:STAGES.index(unit)]}


def test_every_module_belongs_to_a_stage_or_the_low_modules():
    units = {_unit(m) for m in MODULES} - {"aoc_cli"}
    assert units <= set(LOW) | set(STAGES), sorted(units - set(LOW) - set(STAGES))


@pytest.mark.parametrize("unit", LOW + STAGES)
def test_each_stage_imports_only_the_stages_before_it(unit):
    allowed = _allowed(unit)
    upward = sorted({f"{MODULES[m].relative_to(ROOT.parent)}:{line} imports {target}"
              for m in MODULES if _unit(m) == unit
              for target, line in _imports(m, MODULES[m]) if _unit(target) not in allowed})
    assert not upward, "\n".join(upward)


def _cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """The strongly connected components of more than one module (Tarjan)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on: set[str] = set()
    found = []

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        on.add(v)
        for w in sorted(graph[v]):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                found.append(sorted(comp))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return found


def test_no_two_modules_import_each_other():
    graph: dict[str, set[str]] = defaultdict(set)
    for m, path in MODULES.items():
        graph[m]
        for target, _line in _imports(m, path):
            # a package's own __init__ re-exporting its modules is not a circle with them
            if target != m and not (m.startswith(target + ".")):
                graph[m].add(target)
    cycles = _cycles(graph)
    assert not cycles, "\n".join(" <-> ".join(c) for c in cycles)


def test_the_cycle_finder_finds_a_circle_through_three_modules():
    graph = defaultdict(set, {"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}})
    assert _cycles(graph) == [["a", "b", "c"]]


def test_the_module_map_of_the_design_lists_the_stages_in_this_order():
    text = (ROOT.parent / "docs" / "design.md").read_text()
    block = text[text.index("## Module map"):]
    block = block[block.index("```") + 3:]
    block = block[:block.index("```")]
    low_part, stage_part = block.split("the stages, in import order:")
    entries = [[line.split()[0] for line in part.splitlines()
                if line.strip() and line.startswith("  ") and not line.startswith("   ")]
               for part in (low_part, stage_part)]
    low = [name.removesuffix(".py") for name in entries[0] if name.endswith(".py")]
    named = [name.rstrip("/").removesuffix(".py").replace("/", ".") for name in entries[1]]
    path = {s: ROOT / s.replace(".", "/") for s in STAGES}
    assert named == [s for s in STAGES if path[s].exists() or path[s].with_suffix(".py").exists()]
    assert low == LOW


#: Imports of aoc_cli modules inside functions in the library (every module outside cli/), at
#: most this many: each keeps torch, FAISS, matplotlib or the environments (gymnasium) off a
#: path that must not load them (``import aoc_cli``, a model-free rollout, checking training's
#: input, listing the experiments, a rollout without --plot, the command line reading the
#: settings' help), with its reason in a ``# lazy:`` comment on the line or just above the
#: block (docs/design.md, "Module map").
LIBRARY_INNER_IMPORTS = 11
#: The same in cli/: none; a command calls its entry as ``aoc_cli.<entry>``, which the package
#: loads on first use, so ``aoc --help`` stays quick.
CLI_INNER_IMPORTS = 0


def _inner_imports(path: Path) -> list[tuple[int, bool]]:
    """(line, explained) of each import of an aoc_cli module inside a function of ``path``:
    explained when a ``# lazy:`` comment is on its line or above its block of imports."""
    source = path.read_text()
    lines = source.splitlines()
    tree = ast.parse(source)
    imports = [n for f in ast.walk(tree) if isinstance(f, (ast.FunctionDef, ast.AsyncFunctionDef))
               for n in ast.walk(f) if isinstance(n, (ast.Import, ast.ImportFrom))]
    import_lines = {i for n in imports for i in range(n.lineno, n.end_lineno + 1)}
    out = []
    for node in {id(n): n for n in imports}.values():
        names = [a.name for a in node.names] if isinstance(node, ast.Import) else [node.module or ""]
        if not (getattr(node, "level", 0) or any(n.startswith("aoc_cli") for n in names)):
            continue
        above = node.lineno - 1
        while above in import_lines or (above > 0 and not lines[above - 1].strip()):
            above -= 1
        own = " ".join(lines[node.lineno - 1:node.end_lineno])
        out.append((node.lineno, "# lazy:" in own
                    or (above > 0 and lines[above - 1].strip().startswith("# lazy:"))))
    return sorted(out)


def _inner(cli: bool) -> list[tuple[str, bool]]:
    return [(f"{path.relative_to(ROOT.parent)}:{line}", explained)
            for path in sorted(ROOT.rglob("*.py")) if (path.parts[-2] == "cli") == cli
            for line, explained in _inner_imports(path)]


def test_the_library_imports_inside_functions_only_at_the_heavy_dependencies_edge():
    found = _inner(cli=False)
    listing = "\n".join(where for where, _ in found)
    assert len(found) <= LIBRARY_INNER_IMPORTS, f"{len(found)} imports inside functions:\n{listing}"
    unexplained = [where for where, explained in found if not explained]
    assert not unexplained, "no `# lazy:` reason:\n" + "\n".join(unexplained)


def test_the_commands_import_inside_functions_no_more_than_before():
    found = _inner(cli=True)
    assert len(found) <= CLI_INNER_IMPORTS, "\n".join(where for where, _ in found)


def test_the_inner_import_count_sees_a_lazy_import_and_its_reason(tmp_path):
    module = tmp_path / "m.py"
    module.write_text("def f():\n    # lazy: torch\n    import torch\n"
                      "    from aoc_cli.belief import train_model\n"
                      "    from aoc_cli.index.search import BeliefIndex\n\n"
                      "def g():\n    from aoc_cli.store import Store\n    return Store\n")
    assert _inner_imports(module) == [(4, True), (5, True), (8, False)]


#: The house's rule: a few clear modules, none over about this many lines.
MODULE_LINES = 400


def test_no_module_is_over_the_house_size():
    long = {str(p.relative_to(ROOT)): n for p in ROOT.rglob("*.py")
            if (n := len(p.read_text().splitlines())) > MODULE_LINES}
    assert long == {}, f"modules over {MODULE_LINES} lines: split them"
