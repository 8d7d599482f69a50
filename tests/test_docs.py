"""The user documents (README.md, docs/guide/, docs/results/, docs/benchmarks/, docs/design.md)
state what is, not when it was found: no issue number (#NN, "issue NN"), no date (ISO or with a
month's name), and none over 40 KB. History lives in git and in docs/notes/, dated there once."""

import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
LIMIT = 40_000
MONTHS = ("January|February|March|April|May|June|July|August|September|October|November|December"
          "|Jan|Feb|Mar|Apr|Jun|Jul|Aug|Sep|Sept|Oct|Nov|Dec")
PATTERNS = {
    "an issue number": re.compile(r"(?<![\w&])#\d+\b|\bissues? \d+\b", re.I),
    "an ISO date": re.compile(r"\b(?:19|20)\d\d-[01]\d-[0-3]\d\b"),
    "a date with a month's name": re.compile(
        rf"\b(?:[0-3]?\d(?:st|nd|rd|th)? (?:{MONTHS})\.?,? (?:19|20)\d\d"
        rf"|(?:{MONTHS})\.? [0-3]?\d(?:st|nd|rd|th)?,? (?:19|20)\d\d"
        rf"|(?:{MONTHS}) (?:19|20)\d\d)\b"),
}


def user_documents() -> list[Path]:
    pages = [ROOT / "README.md", ROOT / "docs" / "design.md"]
    for folder in ("guide", "results", "benchmarks"):
        pages += sorted((ROOT / "docs" / folder).rglob("*.md"))
    return pages


def findings(path: Path) -> list[str]:
    out = []
    for number, line in enumerate(path.read_text().splitlines(), 1):
        # a colour or an anchor in a link is not an issue number
        text = re.sub(r"\]\([^)]*\)|#[0-9a-fA-F]{6}\b", "", line)
        for what, pattern in PATTERNS.items():
            for match in pattern.finditer(text):
                out.append(f"{path.relative_to(ROOT)}:{number}: {what}: {match.group(0)!r}")
    return out


@pytest.mark.parametrize("path", user_documents(),
                         ids=lambda p: str(p.relative_to(ROOT)))
def test_a_user_document_is_at_most_40_kb(path):
    assert path.stat().st_size <= LIMIT, f"{path.relative_to(ROOT)}: {path.stat().st_size} bytes"


@pytest.mark.parametrize("path", user_documents(), ids=lambda p: str(p.relative_to(ROOT)))
def test_a_user_document_holds_no_issue_number_and_no_date(path):
    found = findings(path)
    assert not found, "\n".join(found)


def test_the_scan_finds_what_it_looks_for(tmp_path):
    page = tmp_path / "page.md"
    page.write_text("fixed in #43; issue 26's split\nrun on 2026-11-29\non 28 Nov 2026\n"
                    "November 26, 2026\ncolour #ff0000 and [a](#anchor-12)\n")
    lines = [f for line in page.read_text().splitlines()
             for f in [any(p.search(re.sub(r"\]\([^)]*\)|#[0-9a-fA-F]{6}\b", "", line))
                           for p in PATTERNS.values())]]
    assert lines == [True, True, True, True, False]


def test_the_user_documents_link_no_removed_page():
    removed = ("docs/results.md", "docs/benchmarks.md", "docs/belief.md", "(results.md)",
               "(benchmarks.md)", "(../results.md)", "(../benchmarks.md)", "(../belief.md)")
    for path in user_documents():
        text = path.read_text()
        assert not [r for r in removed if r in text], path.relative_to(ROOT)


def test_the_results_page_is_one_table_with_a_command_per_row():
    text = (ROOT / "docs" / "results" / "README.md").read_text()
    rows = [line for line in text.splitlines() if line.startswith("| [")]
    assert 5 <= len(rows) <= 30, len(rows)
    assert all("`aoc " in row or "`python " in row for row in rows)
