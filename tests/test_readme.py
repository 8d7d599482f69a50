"""The README stays one that people finish (issue 22): at most 10 KB, and every file it links
to exists."""

import re
from pathlib import Path

README = Path(__file__).resolve().parents[1] / "README.md"


def test_readme_is_at_most_10_kb():
    assert README.stat().st_size <= 10_000, README.stat().st_size


def test_every_relative_link_of_the_readme_exists():
    text = README.read_text()
    links = [m.split("#")[0] for m in re.findall(r"\]\(([^)\s]+)\)", text)
             if not re.match(r"[a-z]+:", m)]
    assert links, "the README links its guide pages"
    missing = [link for link in links if link and not (README.parent / link).exists()]
    assert not missing, missing
