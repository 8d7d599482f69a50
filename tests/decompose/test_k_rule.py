"""The k rule has one home, aoc_cli/decompose/k_rule.py: the index, the decomposition's
default, training's validation and the baselines take their k from it, and a baseline with
another k names it."""

from __future__ import annotations

import ast
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from aoc_cli.baselines.neighbours import knn_k
from aoc_cli.index import model_k
from aoc_cli.decompose import default_k, index_k, per_action_k, subset_size
from aoc_cli.decompose.k_rule import SMALL_MAX_ROWS

PACKAGE = Path(__file__).resolve().parents[2] / "aoc_cli"


def _corpus(rows: int, actions: np.ndarray, discrete: bool = True):
    return SimpleNamespace(name="c", discrete=discrete, n_rows=rows, actions=actions)


def test_the_paper_k_is_twice_the_size_of_a_minimal_subset():
    assert subset_size(20) == 21 and default_k(20) == 42


def test_per_action_k_takes_three_minimal_subsets_of_each_action_present():
    assert per_action_k(20, 2) == 126 and per_action_k(4, 3) == 45   # 3 (d_b + 1) of each
    assert per_action_k(20, 0) == 63  # no action present: one neighbourhood still


@pytest.mark.parametrize("rows,imitation,candidates,expected", [
    (5000, True, "auto", (126, "per_action")),
    (SMALL_MAX_ROWS + 10, True, "auto", (210, "nearest")),   # ceil(21 / 0.1)
    (5000, False, "auto", (42, "nearest")),
    (5000, True, "nearest", (42, "nearest")),
    (SMALL_MAX_ROWS + 10, False, "per_action", (126, "per_action")),
])
def test_the_index_k_follows_the_rule(rows, imitation, candidates, expected):
    actions = np.zeros(rows, np.int64)
    actions[: rows // 10] = 1
    corpus = _corpus(rows, actions)
    assert index_k(20, corpus, imitation, candidates) == expected
    mode = "imitation" if imitation else "value"
    assert model_k(corpus, SimpleNamespace(d_b=20, mode=mode), candidates) == expected


def test_the_index_k_reads_no_actions_when_the_rule_needs_none():
    class NoActions:
        name, discrete, n_rows = "c", False, 10 ** 6

        @property
        def actions(self):
            raise AssertionError("a value index of continuous actions read the actions")

    assert index_k(20, NoActions(), imitation=False) == (42, "nearest")


def test_knn_takes_the_paper_k_not_the_index_k_unless_k_is_set():
    session = SimpleNamespace(model=SimpleNamespace(d_b=20),
                              controller=SimpleNamespace(config=SimpleNamespace(k=None)))
    assert knn_k(session) == 42  # an imitation index of ward would take 126 or 191
    session.controller.config.k = 7
    assert knn_k(session) == 7


def _k_restated(source: str) -> list[int]:
    """Lines computing ``<...d_b...> + 1`` (the rule's d_b + 1) by hand."""
    return [n.lineno for n in ast.walk(ast.parse(source))
            if isinstance(n, ast.BinOp) and isinstance(n.op, ast.Add)
            and isinstance(n.right, ast.Constant) and n.right.value == 1
            and "d_b" in ast.unparse(n.left)]


def test_no_module_outside_the_rule_computes_d_b_plus_one():
    found = [f"{path.relative_to(PACKAGE.parent)}:{line}"
             for path in sorted(PACKAGE.rglob("*.py")) if path.name != "k_rule.py"
             for line in _k_restated(path.read_text())]
    assert not found, "\n".join(found)
    assert _k_restated("k = 2 * (model.d_b + 1)\n") == [1]
