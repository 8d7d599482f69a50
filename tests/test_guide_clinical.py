"""docs/guide/clinical.md is a checked transcript: its commands are run again (the whole
clinical path on a 300-stay synthetic cohort: ingest with gaps, dose bins and outcomes, split,
train, index, a decision page, evaluate with its OPE table) and must print what the page shows.

Up to the split, the output follows from the cohort's seed alone: every line, message, key,
label and table row the same, numbers aside. From ``aoc train`` on, the output follows a
trained network, whose floats move with the CPU (CI runs other CPUs than the one that wrote
the page): which rows support a decision, and whether an estimate passes the OPE's rule, can
change there. Those commands must still run without an error, print JSON of the same keys and
tables of the same titles, headings and row names."""

import importlib.util
import json
import re
import shutil
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PAGE = ROOT / "docs" / "guide" / "clinical.md"
#: The first command whose output follows a trained network.
LEARNED = "aoc train"


def _transcripts():
    spec = importlib.util.spec_from_file_location("transcripts", ROOT / "scripts" /
                                                  "transcripts.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def _commands(text: str) -> list[tuple[str, list[str]]]:
    """(command, its output lines) of every transcript of the page, in order."""
    out: list[tuple[str, list[str]]] = []
    inside = False
    for line in text.split("\n"):
        if line.startswith("```console"):
            inside = True
        elif line.startswith("```"):
            inside = False
        elif inside and line.startswith("$ "):
            out.append((line[2:], []))
        elif inside and out:
            out[-1][1].append(line)
    return out


def _words(lines: list[str]) -> list[str]:
    """The words of some output, numbers as '#' and table rules collapsed (table cells wrap
    differently when a number's width changes)."""
    text = "\n".join(lines)
    text = re.sub(r"-?\d+(?:[.,]\d+)*(?:e[-+]?\d+)?", "#", text)
    text = re.sub(r"[─━═]+", "─", text)
    return text.split()


def _keys(value) -> object:
    """A JSON value's shape: its keys, recursively (a list by its first item)."""
    if isinstance(value, dict):
        return {k: _keys(v) for k, v in value.items()}
    if isinstance(value, list):
        return [_keys(value[0])] if value else []
    return type(value).__name__ if value is not None else "null"


def _outline(lines: list[str]) -> list:
    """What a learned command's output must keep: JSON lines by their keys, a table by its
    titles, headings and row names (a table's first column), never its numbers."""
    out: list = []
    for line in lines:
        stripped = line.strip()
        if stripped[:1] in "{[":
            out.append(_keys(json.loads(stripped)))
        elif stripped.startswith("aoc: warning:"):
            continue  # a warning names what the numbers showed
        elif stripped.startswith(("┃", "│")):
            first = stripped.strip("┃│").split("│")[0].split("┃")[0].strip()
            if first and not re.fullmatch(r"[-\d.,e+ /]*", first):
                out.append(re.sub(r"\d+", "#", first))
        elif stripped and not stripped[0] in "┌┏┡└├╞┗":
            out.append(" ".join(_words([stripped])[:2]))  # a table's title, a verdict's start
    return out


@pytest.mark.quality
def test_the_clinical_guide_prints_what_it_shows(tmp_path):
    # the page's commands pipe through jq and run under script(1): .ci/run installs both
    missing = [tool for tool in ("jq", "script") if shutil.which(tool) is None]
    assert not missing, f"install {missing} (Debian: jq, bsdutils) to check the clinical guide"
    text = PAGE.read_text()
    fresh = _transcripts().refresh(text, tmp_path)
    assert "Traceback" not in fresh and "internal error" not in fresh
    assert "aoc: error" not in fresh.split(LEARNED, 1)[1]
    now, shown = _commands(fresh), _commands(text)
    assert [c for c, _ in now] == [c for c, _ in shown]
    learned = False
    for (command, lines), (_, page) in zip(now, shown):
        learned = learned or command.startswith(LEARNED)
        if learned:
            assert _outline(lines) == _outline(page), command
        else:
            assert _words(lines) == _words(page), command
