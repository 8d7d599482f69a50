"""The store's root and layout have one home, aoc_cli/store/layout.py: the root rule
(--store, else $AOC_STORE, else ./corpora), the model and index folders, and the default ids.
No other module spells them out."""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

from aoc_cli.errors import AocError
from aoc_cli.store import Store, layout
from tests.conftest import run_in_process

PACKAGE = Path(layout.__file__).resolve().parents[1]


def test_the_root_is_the_given_folder_first(tmp_path, monkeypatch):
    monkeypatch.setenv(layout.STORE_ENV, str(tmp_path / "env"))
    assert layout.store_root(tmp_path / "given") == tmp_path / "given"
    assert Store.open(tmp_path / "given").root == tmp_path / "given"


def test_the_root_is_the_environment_variable_when_none_is_given(tmp_path, monkeypatch):
    monkeypatch.setenv(layout.STORE_ENV, str(tmp_path / "env"))
    assert layout.store_root() == tmp_path / "env"
    assert Store.open().root == tmp_path / "env"


@pytest.mark.parametrize("value", [None, ""])
def test_the_root_is_corpora_in_the_working_folder_without_either(monkeypatch, value):
    if value is None:
        monkeypatch.delenv(layout.STORE_ENV, raising=False)
    else:
        monkeypatch.setenv(layout.STORE_ENV, value)
    assert layout.store_root() == Path("corpora")


def test_the_cli_reads_the_root_from_the_environment_through_the_layout(tmp_path, monkeypatch,
                                                                        capsys):
    monkeypatch.setenv(layout.STORE_ENV, str(tmp_path / "s"))
    (tmp_path / "s").write_text("not a folder")
    code, _out, err = run_in_process(capsys, "ls")
    assert code == 2 and f"store {tmp_path / 's'} is not a folder" in err


def test_model_and_index_folders_sit_under_the_corpus(tmp_path):
    corpus = tmp_path / "c"
    assert layout.model_dir(corpus, "m") == corpus / "models" / "m"
    assert layout.index_dir(corpus, "m", "i") == corpus / "models" / "m" / "index" / "i"


@pytest.mark.parametrize("bad", ["../x", "a/b", "", ".hidden"])
def test_a_model_or_index_id_that_is_no_store_name_is_refused(tmp_path, bad):
    with pytest.raises(AocError, match="invalid model name"):
        layout.model_dir(tmp_path, bad)
    with pytest.raises(AocError, match="invalid index name"):
        layout.index_dir(tmp_path, "m", bad)


def _spelled_out(source: str, name: str) -> list[str]:
    """Lines of a module that spell the layout out: the bare ``"default"`` id, or a path
    joined with ``/ "models"`` or ``/ "index"``."""
    found = []
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.Constant) and node.value == layout.DEFAULT_MODEL:
            found.append(f"{name}:{node.lineno} \"default\"")
        elif isinstance(node, ast.BinOp) and isinstance(node.op, ast.Div) \
                and isinstance(node.right, ast.Constant) \
                and node.right.value in (layout.MODELS, layout.INDEXES):
            found.append(f"{name}:{node.lineno} / {node.right.value!r}")
    return found


def test_no_module_but_the_layout_spells_out_the_default_ids_or_the_folders():
    found = [hit for path in sorted(PACKAGE.rglob("*.py"))
             if path != Path(layout.__file__).resolve()
             for hit in _spelled_out(path.read_text(), str(path.relative_to(PACKAGE.parent)))]
    assert not found, "\n".join(found)


def test_the_scan_finds_a_bare_default_id_and_a_hand_built_model_folder():
    hits = _spelled_out('def f(corpus):\n    return corpus.path / "models" / "default"\n', "m")
    assert hits == ["m:2 / 'models'", 'm:2 "default"']
