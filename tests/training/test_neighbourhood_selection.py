"""Rule 6 on continuous observations (aoc_cli.training.controller_selection under rule 7's
premise, docs/design.md "Settings from the log's evidence"): on a log whose observations never
repeat, ``aoc train`` weighs rule 7's controller against the paper's on held-out episodes, a
decision's support counted in the held-out episodes among the rows nearest its step (the
continuous form of "held out fewer than 3 times in that state"), and keeps rule 7 where the
paper's decisions are ones the held-out log hardly holds."""

import json

import numpy as np
import pytest

import aoc_cli
from aoc_cli.envs import collect
from aoc_cli.store import Store
from aoc_cli.index.search.denoise import CAP, LEAST
from aoc_cli.index.search.neighbourhood import Neighbourhood, episodes_near
from aoc_cli.training import controller_selection as cs


def brute_counts(logged, starts, n, sets):
    """(R, n) by hand: the distinct episodes among the rows of each row's set, per action."""
    episode = np.repeat(np.arange(len(starts) - 1), np.diff(starts))
    out = np.zeros((len(sets), n), np.int64)
    for i in range(len(sets)):
        near = sets[i]
        for a in range(n):
            out[i, a] = len(set(episode[near][logged[near] == a].tolist()))
    return out


@pytest.mark.parametrize("rows", [40, 180, 1500])
def test_the_support_near_a_step_is_the_distinct_episodes_of_its_neighbourhood(rows):
    """Rule 7's sets (every row near the row's denoised observation: tests/index/
    test_denoise.py checks them against a brute-force search), each row's own among them."""
    rng = np.random.default_rng(rows)
    obs = rng.normal(size=(rows, 3)) * [1.0, 5.0, 0.2]    # columns on different scales
    logged = rng.integers(0, 4, rows)
    starts = np.r_[0, np.sort(rng.choice(np.arange(1, rows), 9, replace=False)), rows]
    got = episodes_near(obs, logged, starts, 4)
    assert got.shape == (rows, 4)
    sets = Neighbourhood(obs, logged, np.zeros(rows, np.int64), 4).sets(obs)
    assert all(i in sets[i] for i in range(rows))
    assert sets.sizes.min() >= min(LEAST, rows) and sets.sizes.max() <= CAP
    assert np.array_equal(got, brute_counts(logged, starts, 4, sets))


def test_a_screened_or_lone_candidate_has_no_estimate_and_rule_7_is_kept():
    span = (0.0, 1.0)
    rule7 = {"low": 0.70, "estimate": 0.75, "pairs": 22, "rare": 0.01}
    # the paper's, screened out at 500 steps: never chosen, however high its interval
    paper = {"low": None, "estimate": None, "pairs": 1, "rare": 0.7, "screened": 500}
    assert cs.valued([rule7, paper], span)[1].startswith("fewer than 3 at 500 held-out steps")
    assert cs.pick([rule7, paper], span) == 0
    assert cs.bounds([rule7, paper], span)[1] == -np.inf
    # rule 7 alone (no other candidate fitted): no estimate of its own, and kept
    alone = {"low": None, "estimate": None, "pairs": 22, "rare": 0.01, "alone": True}
    assert cs.valued([alone, paper], span)[0].startswith("no other candidate")
    assert cs.pick([alone, paper], span) == 0
    # a paper's candidate fitted and well held, with the higher bound, is chosen
    fitted = {"low": 0.76, "estimate": 0.80, "pairs": 9, "rare": 0.02}
    assert cs.pick([rule7, fitted], span) == 1


@pytest.fixture(scope="module")
def cohort(tmp_path_factory):
    """A 300-stay cohort at noise 0.3 (no observation repeats) trained as ``aoc train``
    trains it, with the notes it printed."""
    from tests.conftest import run_aoc

    store = Store(tmp_path_factory.mktemp("cohort-select"))
    data, _ = collect("icu-cohort", episodes=300, seed=0)
    store.write("c", data)
    code, out, err = run_aoc("--store", str(store.root), "train", "c", "--threads", "1",
                             "--epochs", "2", "--hidden", "8", "--format", "json")
    assert code == 0, err
    return store, json.loads(out), err          # aoc train's notes: on stderr, in any format


def test_train_weighs_rule_7_against_the_papers_on_held_out_episodes(cohort):
    store, metrics, printed = cohort
    out = metrics["settings"]["controller_selection"]
    assert [c["settings"] for c in out["candidates"]] == list(cs.HARM)
    rule7, paper = out["candidates"]
    # the paper's decisions on noisy features are ones the held-out log hardly holds:
    # screened at a sample of steps, never fitted, never chosen
    assert paper["screened"] == min(cs.SCREEN, out["steps"])
    assert paper["pairs"] < cs.MIN_PAIRS and not paper["valued"]
    assert paper["estimate"] is None and paper["bound"] is None
    # rule 7's decisions keep the clinicians' likely dose where no bound beats it: held
    assert rule7["pairs"] >= cs.MIN_PAIRS and rule7["rare"] < paper["rare"]
    assert 0.0 < rule7["agrees"] <= 1.0
    assert out["chosen"] == {"do_no_harm": "on"}
    assert metrics["controller"]["do_no_harm"] == "on"
    assert "in that state\" is among the held-out rows near the step" in out["rule"]
    why = {r["setting"]: r["why"] for r in metrics["settings"]["decided"]}
    assert why["do_no_harm"].startswith("chosen among 2 controllers by the highest lower")
    assert "rule 7's is kept when it has none" in why["do_no_harm"]
    assert why["do_no_harm"].endswith("another's bound beats its own (rule 7)")  # why it decides
    # aoc train's table says which rule decided and why the other was not weighed
    flat = " ".join(printed.split())
    assert "rule 7 (do no harm)" in flat and "<- chosen" in flat
    assert "the paper's (no do no harm) FQE not fitted, decided at" in flat
    aoc_cli.build_index("c", store=store.root)
    session = aoc_cli.open_session("c", store=store.root)
    assert session.controller.config.do_no_harm == "on"


def test_do_no_harm_given_skips_the_choice(cohort, aoc):
    store = cohort[0]
    code, out, err = aoc("--store", str(store.root), "train", "c", "--model", "given",
                         "--do-no-harm", "off", "--threads", "1", "--epochs", "1",
                         "--hidden", "8", "--format", "json")
    assert code == 0, err
    metrics = json.loads(out)
    assert "controller_selection" not in metrics["settings"]
    assert metrics["controller"]["do_no_harm"] == "off"
