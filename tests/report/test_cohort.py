"""The cohort report (``aoc evaluate --html``): every section in a real browser (headless
Chromium), for a value-mode evaluation with its OPE (estimates withheld, and the same report
with them shown) and an imitation-mode one; the decision pages it links open; nothing from a
log runs in it."""

from __future__ import annotations

import copy
import json
import re
from pathlib import Path

import pytest

from aoc_cli.belief import BeliefConfig, train_model
from aoc_cli.envs import collect
from aoc_cli.index import build_index
from aoc_cli.report.cohort import cohort_page
from aoc_cli.store import Store
from tests.control.corpora import HOSTILE_TAGS, hostile_corridor_store

NO_PROBLEMS = {"exceptions": [], "dialogs": [], "requests": [], "errors": []}
SECTIONS = ["verdict", "values", "support", "agreement", "residuals", "steps"]


@pytest.fixture(scope="module")
def sepsis(tmp_path_factory):
    """A small icu-sepsis log (value mode, discrete actions, a propensity column)."""
    root = tmp_path_factory.mktemp("cohort-sepsis")
    store = Store(root)
    store.write("icu", collect("icu-sepsis", episodes=200, seed=0)[0])
    held = collect("icu-sepsis", episodes=60, seed=1)[0]
    store.write("held", held)
    held.columns = {k: v for k, v in held.columns.items() if k != "propensity"}
    store.write("held-plain", held)     # no propensity column: the behaviour is estimated
    corpus = store.corpus("icu")
    train_model(corpus, BeliefConfig(history_length=0, hidden=16, belief_dim=4, max_epochs=2,
                                     threads=1, seed=0), "default")
    build_index(corpus, "default")
    return root


@pytest.fixture(scope="module")
def corridor(tmp_path_factory):
    root = tmp_path_factory.mktemp("cohort-corridor")
    hostile_corridor_store(root)
    return root


def _run(aoc_inproc, root, *args):
    code, out, err = aoc_inproc("--store", str(root), *args)
    assert code == 0, err
    return out


def _sections(browser) -> list[str]:
    return browser.evaluate("[...document.querySelectorAll('section')].map(s => s.id)")


def _check_links(browser, report: Path, expected: int) -> list[str]:
    """The steps' links: relative, to pages that exist and open without a problem."""
    links = browser.evaluate("[...document.querySelectorAll('#steps a')].map(a => "
                             "a.getAttribute('href'))")
    assert len(links) == expected
    for href in links[:2]:
        assert not href.startswith(("/", "http", "file:"))
        page = report.parent / href
        assert page.is_file()
        browser.open(page)
        assert browser.problems() == NO_PROBLEMS
        assert browser.evaluate("document.querySelectorAll('#decision .lede').length") == 1
    return links


def test_a_value_report_with_withheld_estimates(aoc_inproc, sepsis, tmp_path, browser):
    report = tmp_path / "report.html"
    doc = json.loads(_run(aoc_inproc, sepsis, "evaluate", "icu", "--data", "held",
                          "--baselines", "bc", "--ope", "pdwis,wdr", "--fqe-steps", "100",
                          "--html", str(report), "--top", "4", "--by", "state", "-f", "json"))
    # 60 episodes: an ESS under the rule's 500, so both estimates are withheld
    assert doc["policy_value"]["pdwis"]["estimate"] is None
    text = report.read_text()
    assert "<script" not in text.lower() and "default-src 'none'" in text
    browser.open(report)
    assert browser.problems() == NO_PROBLEMS
    assert _sections(browser) == SECTIONS
    lede = browser.evaluate("document.querySelector('#verdict .lede').innerText")
    assert lede == doc["verdict"][0].upper() + doc["verdict"][1:] + "."
    assert lede.startswith("Better or worse than the logged behaviour: not estimable")
    rows = browser.evaluate("[...document.querySelectorAll('svg.forest .forest-row')].map(g =>"
                            " [g.dataset.policy, g.dataset.estimator, g.dataset.withheld, "
                            "g.textContent])")
    own = {est: (w, t) for p, est, w, t in rows if p == "aoc"}
    assert set(own) == {"pdwis", "wdr"}
    for est, (withheld, shown) in own.items():
        reason = doc["policy_value"][est]["reason"]
        assert withheld == "true" and "withheld: " + reason[:60] in shown
        assert not re.search(r"\d\.\d{3}", shown.replace(reason[:108], ""))  # no number
    behaviour = [r for r in rows if r[0] == "logged behaviour" and r[1] == "mean return"]
    assert behaviour and behaviour[0][2] == "false"
    assert f"{doc['behaviour_value']['estimate']:.4g}" in behaviour[0][3]
    assert "bc" in {r[0] for r in rows}
    # support: the ESS per step and the calibration of... a column's propensities: none
    assert browser.evaluate("document.querySelectorAll('#support svg').length") >= 1
    cells = browser.evaluate("[...document.querySelectorAll('svg.heatmap rect.cell')].map("
                             "r => +r.dataset.count)")
    assert sum(cells) == doc["steps"]
    assert browser.evaluate("document.querySelectorAll('#by + table tr').length") >= 2
    assert browser.evaluate("document.querySelectorAll('svg.histogram rect.bar').length") > 1
    _check_links(browser, report, 4)
    assert (tmp_path / "report-pages").is_dir()


def test_a_value_report_with_estimates_shown(sepsis, tmp_path, browser):
    """The same evaluation's report with the estimates the rule withheld given numbers: each
    is drawn as a point and its interval, with no reason."""
    import aoc_cli

    ev = aoc_cli.evaluate("icu", "held-plain", store=sepsis, baselines=[], ope="pdwis")
    c = ev.cohort(top=0)
    assert c["support"]["calibration"]          # the estimated propensities' calibration bins
    shown = copy.deepcopy(c)
    for r in shown["forest"]:
        if r["estimate"] is None:
            r.update(estimate=0.7, low=0.6, high=0.8, reason=None)
    page = tmp_path / "shown.html"
    page.write_text(cohort_page(shown))
    browser.open(page)
    assert browser.problems() == NO_PROBLEMS
    rows = browser.evaluate("[...document.querySelectorAll('svg.forest .forest-row')].map(g =>"
                            " [g.dataset.withheld, g.querySelectorAll('rect').length, "
                            "g.textContent])")
    assert rows and all(w == "false" and n == 1 and "withheld" not in t for w, n, t in rows)
    assert any("0.7 [0.6, 0.8]" in t for _, _, t in rows)
    charts = browser.evaluate("[...document.querySelectorAll('#support svg')].map(s => "
                              "s.getAttribute('aria-label'))")
    assert any(a.startswith("propensity model's calibration") for a in charts)
    assert browser.evaluate("document.querySelectorAll('#steps a').length") == 0
    # the notebook's view of the same evaluation: the report's body, no script, no links
    html = ev._repr_html_()
    assert html.startswith('<div class="aoc-page"><style>') and "<script" not in html
    assert "withheld: " in html


def test_an_imitation_report_with_hostile_tags(aoc_inproc, corridor, tmp_path, browser):
    report, pages = tmp_path / "abc.html", tmp_path / "pages"
    pages.mkdir()
    doc = json.loads(_run(aoc_inproc, corridor, "evaluate", "corridor", "--data", "corridor",
                          "--baselines", "knn", "--html", str(report), "--pages", str(pages),
                          "--top", "3", "--by", "clinician", "-f", "json"))
    assert doc["mode"] == "imitation"
    text = report.read_text()
    assert "<script" not in text.lower() and "<img" not in text
    assert re.search(r"<[^>]*\son(error|load)=", text) is None
    browser.open(report)
    assert browser.problems() == NO_PROBLEMS
    assert _sections(browser) == SECTIONS
    lede = browser.evaluate("document.querySelector('#verdict .lede').innerText")
    assert lede.startswith("Imitation: the decision is the logged action at")
    assert "No offline policy evaluation" in browser.evaluate(
        "document.querySelector('#values').innerText")
    by = browser.evaluate("document.querySelector('#agreement').innerText")
    assert any(t in by for t in HOSTILE_TAGS)            # the markup shown as text
    assert browser.evaluate("document.querySelectorAll('script, img, iframe').length") == 0
    links = _check_links(browser, report, 3)
    assert all(link.startswith("pages/") for link in links)


def test_the_cohort_data_of_a_bad_by_and_top(aoc_inproc, corridor, tmp_path):
    code, _out, err = aoc_inproc("--store", str(corridor), "evaluate", "corridor", "--data",
                                 "corridor", "--baselines", "none", "--html",
                                 str(tmp_path / "r.html"), "--by", "nothing")
    assert code == 2 and "--by 'nothing' is no tag" in err
    code, _out, err = aoc_inproc("--store", str(corridor), "evaluate", "corridor", "--data",
                                 "corridor", "--pages", str(tmp_path))
    assert code == 2 and "--html" in err
