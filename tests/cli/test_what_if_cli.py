"""`aoc explain --without` and `aoc evaluate --without` from the command line."""

import json
import re

import pytest

from tests.control.corpora import HOSTILE_TAGS, hostile_corridor_store


@pytest.fixture(scope="module")
def root(tmp_path_factory):
    root = tmp_path_factory.mktemp("cli-whatif")
    hostile_corridor_store(root)
    return root


@pytest.fixture
def run(aoc_inproc, root):
    return lambda *args: aoc_inproc("--store", str(root), *args)


def one_line_error(code, out, err, pattern):
    assert code == 2 and out == "", (code, out, err)
    lines = err.strip().splitlines()
    assert len(lines) == 1 and re.search(pattern, lines[0]), err


def test_explain_without_a_tag_value_reports_the_new_decision_and_its_rows(run):
    code, out, err = run("explain", "corridor", "--data", "corridor", "--episode", "4",
                         "--step", "5", "--without", f"clinician={HOSTILE_TAGS[0]}",
                         "-f", "json")
    assert code == 0, err
    rec = json.loads(out)
    w = rec["what_if"]
    assert w["without"]["label"] == f"clinician={HOSTILE_TAGS[0]}"
    assert w["without"]["episodes"] == 20 and w["without"]["rows"] == 240
    assert all(s["tags"]["clinician"] != HOSTILE_TAGS[0] for s in w["support"])
    removed = [s["row"] for s in rec["support"] if s["tags"]["clinician"] == HOSTILE_TAGS[0]]
    assert w["support_removed"] == removed
    assert w["unchanged"] == (not removed and w["support"] == rec["support"])
    assert set(w) >= {"action", "value", "residual", "action_changed", "residual_change"}


def test_evaluate_without_episodes_reports_flips_and_the_score_change(run):
    code, out, err = run("evaluate", "corridor", "--data", "corridor", "--baselines", "none",
                         "--without-episodes", "p00,p02,p04,7", "-f", "json")
    assert code == 0, err
    w = json.loads(out)["what_if"]
    assert w["without"] == {"label": "episodes p00,p02,p04,7", "rows": 48, "episodes": 4}
    assert w["steps"] == 720 and 0 <= w["flipped"] <= w["steps"]
    assert w["flip_share"] == pytest.approx(w["flipped"] / 720)
    assert 0 < w["support_removed_steps"] < 720
    assert {"accuracy", "auc"} <= set(w["after"])


@pytest.mark.parametrize("command", ["explain", "evaluate"])
@pytest.mark.parametrize("flags, pattern", [
    (["--without", "clinician=c9"], r"tag 'clinician' has no value 'c9' \(values: "),
    (["--without", "ward=a"], r"no tag 'ward'"),
    (["--without", "clinician"], r"--without expects TAG=VALUE"),
    (["--without-episodes", "p99"], r"no episode 'p99'"),
    (["--without", "clinician=" + ",".join(HOSTILE_TAGS)], r"removes every row"),
])
def test_bad_removals_are_one_line_and_exit_2(run, command, flags, pattern):
    where = ["--episode", "0", "--step", "1"] if command == "explain" else []
    one_line_error(*run(command, "corridor", "--data", "corridor", *where, *flags), pattern)
