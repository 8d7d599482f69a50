"""docs/guide/notebook.md runs as it stands: its ``python`` blocks, in order, in one namespace,
in a fresh folder (its ``py`` blocks are illustrations and are not run). No block warns that
it uses a deprecated argument."""

from __future__ import annotations

import re
import warnings
from pathlib import Path

PAGE = Path(__file__).resolve().parents[1] / "docs" / "guide" / "notebook.md"


def blocks(text: str) -> list[str]:
    return re.findall(r"^```python\n(.*?)^```", text, flags=re.S | re.M)


def test_the_notebook_guide_runs_end_to_end(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    code = blocks(PAGE.read_text())
    assert len(code) >= 6
    namespace: dict = {}
    with warnings.catch_warnings():
        warnings.simplefilter("error", DeprecationWarning)
        warnings.filterwarnings("ignore", message=".*has no __module__ attribute")
        for i, block in enumerate(code):
            exec(compile(block, f"{PAGE.name} block {i}", "exec"), namespace)
    assert (tmp_path / "report.html").is_file() and (tmp_path / "report-pages").is_dir()
    assert len(list((tmp_path / "report-pages").glob("*.html"))) == 4
    assert "candidates=" in repr(namespace["decision"]) and "\n" not in repr(namespace["decision"])
