"""docs/guide/clinical.md is a checked transcript: its commands are run again (the whole
clinical path on a 300-stay synthetic cohort: ingest with gaps, dose bins and outcomes, split,
train, index, a decision page, evaluate with its OPE table) and must print what the page shows,
numbers aside (they move with the machine's floating point and timings): every line, message,
key, label and table row the same."""

import importlib.util
import re
import shutil
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PAGE = ROOT / "docs" / "guide" / "clinical.md"


def _transcripts():
    spec = importlib.util.spec_from_file_location("transcripts", ROOT / "scripts" /
                                                  "transcripts.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def shape(text: str) -> list[str]:
    """The page's transcript lines with numbers as '#' and table padding collapsed."""
    lines = []
    inside = False
    for line in text.split("\n"):
        if line.startswith("```console"):
            inside = True
        elif line.startswith("```"):
            inside = False
        elif inside:
            line = re.sub(r"-?\d+(?:[.,]\d+)*(?:e[-+]?\d+)?", "#", line)
            line = re.sub(r"[─━═]+", "─", line)
            line = re.sub(r"[ ]+", " ", line).strip()
            lines.append(line)
    return [ln for ln in lines if ln.strip("│┃ ")]


@pytest.mark.quality
def test_the_clinical_guide_prints_what_it_shows(tmp_path):
    # the page's commands pipe through jq and run under script(1): .ci/run installs both
    missing = [tool for tool in ("jq", "script") if shutil.which(tool) is None]
    assert not missing, f"install {missing} (Debian: jq, bsdutils) to check the clinical guide"
    text = PAGE.read_text()
    fresh = _transcripts().refresh(text, tmp_path)
    assert "Traceback" not in fresh and "internal error" not in fresh
    now, shown = shape(fresh), shape(text)
    # table cells wrap differently when a number's width changes: compare the words
    assert " ".join(now).split() == " ".join(shown).split()
