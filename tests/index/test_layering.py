"""The flow reads one way (store -> belief -> index.search -> decompose -> index -> control): the
index room's search floor (aoc_cli.index.search) knows only beliefs, so importing it must not
import torch or anything above it, not even the corpus index of its own room."""

import subprocess
import sys


def _modules_after(statement: str) -> set[str]:
    code = f"import sys; {statement}; print(' '.join(sorted(sys.modules)))"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True)
    return set(out.stdout.split())


def test_index_depends_on_numpy_and_faiss_only():
    mods = _modules_after("from aoc_cli.index.search import BeliefIndex, IndexConfig, PerAction")
    assert "faiss" in mods and "numpy" in mods
    assert "torch" not in mods
    above = {m for m in mods if m.startswith(("aoc_cli.decompose", "aoc_cli.control",
                                              "aoc_cli.belief", "aoc_cli.index."))
             and not m.startswith("aoc_cli.index.search")}
    assert not above, above


def test_belief_artefact_and_train_import_in_either_order():
    # no import cycle between the two: each loads on its own, first
    for first in ("aoc_cli.belief.artefact", "aoc_cli.belief.train"):
        assert first in _modules_after(f"import {first}")


def test_the_index_settings_load_without_faiss():
    # the package loads its names on first use: aoc index --help reads IndexConfig's fields
    mods = _modules_after("from aoc_cli.index.search.config import IndexConfig")
    assert "faiss" not in mods and "torch" not in mods
