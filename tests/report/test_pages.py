"""The decision and overview pages (``aoc explain --html``): what they hold, that nothing
from a log runs in them, and what a person sees in a real browser (headless Chromium)."""

from __future__ import annotations

import json
import re
from pathlib import Path

import pytest

from tests.control.corpora import HOSTILE_TAGS, hostile_corridor_store
from tests.explanation.test_whatif import maze  # noqa: F401 (fixture)

HOSTILE_ID = "<img src=x onerror=alert(3)>"


@pytest.fixture(scope="module")
def corridor_root(tmp_path_factory):
    root = tmp_path_factory.mktemp("pages")
    hostile_corridor_store(root)
    return root


def aoc(aoc_inproc, root, *args):
    code, out, err = aoc_inproc("--store", str(root), *args)
    assert code == 0, err
    return out


@pytest.fixture
def ward_page(aoc_inproc, corridor_root, tmp_path):
    """An imitation decision of the hostile corpus, with a what-if: (page path, its JSON)."""
    page = tmp_path / "decision.html"
    out = aoc(aoc_inproc, corridor_root, "explain", "corridor", "--data", "corridor",
              "--episode", "1", "--step", "4", "--without", f"clinician={HOSTILE_TAGS[2]}",
              "--html", str(page), "-f", "json")
    return page, json.loads(out)


@pytest.fixture
def audit_page(aoc_inproc, maze, tmp_path):
    """A value-mode audit log of two maze episodes and the page of its step 3 of episode 1."""
    root = maze.root
    log, page = tmp_path / "audit.h5", tmp_path / "audit.html"
    aoc(aoc_inproc, root, "rollout", "maze", "--env", "maze", "-n", "2", "--seed", "4",
        "--audit", str(log), "-f", "json")
    out = aoc(aoc_inproc, root, "explain", "maze", "--audit", str(log), "--episode", "1",
              "--step", "3", "--html", str(page), "-f", "json")
    import h5py

    with h5py.File(log) as f:
        residuals, flags = f["episode_1/residuals"][()], f["episode_1/ood"][()]
    return page, json.loads(out), residuals, flags


def test_the_page_shows_markup_from_the_log_as_text(ward_page):
    page, rec = ward_page
    text = page.read_text()
    assert "<script" not in text.lower() and "<img" not in text
    # no tag of the page carries an event handler: the ones from the log stay text
    assert re.search(r"<[^>]*\son(error|load)=", text) is None
    assert "&lt;img src=x onerror=alert(3)&gt;" in text
    assert "&lt;script&gt;alert(1)&lt;/script&gt;" in text or "&quot; onload=&quot;" in text
    assert "Content-Security-Policy" in text and "default-src 'none'" in text
    # nothing is fetched: no src or href but in-page anchors
    assert re.search(r'<[^>]*\ssrc=', text) is None
    assert all(h.startswith("#") for h in re.findall(r'href="([^"]*)"', text))
    # one card per supporting row, each with its history plot
    assert text.count('class="card"') == len(rec[0]["support"] if isinstance(rec, list)
                                               else rec["support"])
    # the decided action's score, and each card's label of the row (row labels, ABC)
    rec = rec[0] if isinstance(rec, list) else rec
    assert f"score {rec['scores'][rec['action']]:.0%} (weight x label over the rows)" in text
    assert text.count("&middot; label ") >= len(rec["support"])


def test_a_decision_page_in_the_browser(ward_page, browser):
    page, rec = ward_page
    browser.open(page)
    assert browser.problems() == {"exceptions": [], "dialogs": [], "requests": [],
                                  "errors": []}
    text = browser.evaluate("document.body.innerText")
    lede = browser.evaluate("document.querySelector('#decision .lede').innerText")
    n = len({s["episode"] for s in rec["support"]})
    assert f"supported by {n} past patients ({len(rec['support'])} rows)" in lede
    assert re.search(r"residual [0-9.e+-]+x typical", lede)
    cards = browser.evaluate("[...document.querySelectorAll('#decision .card')].map("
                             "c => [c.dataset.row, c.querySelectorAll('svg polyline').length])")
    assert [int(r) for r, _ in cards] == [s["row"] for s in rec["support"]]
    assert all(lines >= 2 for _, lines in cards)  # the row's and the query's history
    assert "Why not" in text and rec["contrast"]["why"]["text"] in text
    assert f"What if the corpus had no clinician={HOSTILE_TAGS[2]}?" in text
    # the hostile text is visible as text
    seen = [t for t in HOSTILE_TAGS[:2] + [HOSTILE_ID] if t in text]
    assert seen, "no hostile tag value or id among the shown rows"
    assert browser.evaluate("document.querySelectorAll('script, img, iframe').length") == 0


def test_an_audit_overview_links_every_step_to_its_section(audit_page, browser):
    page, rec, residuals, flags = audit_page
    browser.open(page)
    assert browser.problems() == {"exceptions": [], "dialogs": [], "requests": [],
                                  "errors": []}
    steps = browser.evaluate("[...document.querySelectorAll('.step')].map(s => s.id)")
    assert steps == [f"step-1-{t}" for t in range(len(residuals))]
    targets = browser.evaluate("[...document.querySelectorAll('svg a')].map(a => "
                               "a.getAttribute('href'))")
    assert set(targets) >= {f"#step-1-{t}" for t in range(len(residuals))}
    flagged = browser.evaluate("document.querySelectorAll('.step.flag').length")
    assert flagged == int(flags.sum())
    assert browser.evaluate("document.querySelectorAll('#decision .card').length") == \
        len(rec["support"])
    assert browser.evaluate("!!document.querySelector('#step-1-3 a[href=\"#decision\"]')")


def test_the_browser_check_sees_an_alert_an_error_and_a_request(tmp_path, browser):
    bad = tmp_path / "bad.html"
    bad.write_text("<html><body><script>alert('x'); undefinedFunction();</script>"
                   "<img src='http://192.0.2.1/x.png'></body></html>")
    browser.open(bad)
    p = browser.problems()
    assert p["dialogs"] == ["x"] and p["exceptions"] and p["requests"]


def test_an_evaluate_steps_file_gets_an_overview(aoc_inproc, corridor_root, tmp_path, browser):
    steps, page = tmp_path / "steps.jsonl", tmp_path / "steps.html"
    aoc(aoc_inproc, corridor_root, "evaluate", "corridor", "--data", "corridor",
        "--baselines", "none", "--steps", str(steps), "-f", "json")
    aoc_inproc("--store", str(corridor_root), "explain", "corridor", "--steps", str(steps),
               "--html", str(page))
    browser.open(page)
    assert browser.problems()["exceptions"] == []
    n = sum(1 for line in steps.read_text().splitlines() if line.strip())
    assert browser.evaluate("document.querySelectorAll('.step').length") == n
    assert browser.evaluate("document.querySelectorAll('section').length") == 60


@pytest.mark.parametrize("where, pattern", [
    ("store", r"inside the corpus store"),
    ("/proc/aoc-page.html", r"not writable|cannot write"),
    ("missing/x.html", r"does not exist"),
])
def test_bad_html_paths_are_one_line_and_exit_2(aoc_inproc, corridor_root, tmp_path, where,
                                                pattern):
    path = {"store": str(Path(corridor_root) / "corridor" / "x.html"),
            "missing/x.html": str(tmp_path / "missing" / "x.html")}.get(where, where)
    code, out, err = aoc_inproc("--store", str(corridor_root), "explain", "corridor",
                                "--data", "corridor", "--episode", "0", "--step", "1",
                                "--html", path)
    lines = err.strip().splitlines()
    assert code == 2 and out == "" and len(lines) == 1 and re.search(pattern, lines[0]), err
