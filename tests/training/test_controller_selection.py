"""The controller chosen on held-out episodes (aoc_cli.training.controller_selection, rule 6 of
docs/design.md "Settings from the log's evidence"): each candidate decides by the controller's
own rule, the rule takes the highest lower bound (ties: the more conservative), ``aoc train``
records what it chose and why, a setting given or --no-select skips it; the k saved with the
model reaches the index and every decision unless --k is given."""

import json

import numpy as np
import pytest

import aoc_cli
from aoc_cli.envs import collect
from aoc_cli.training import controller_selection
from aoc_cli.store import Store
from tests.plain_log import write_plain_npz


def test_the_rule_takes_the_highest_lower_bound_and_the_first_of_equals():
    assert controller_selection.pick([{"low": 0.5}, {"low": 0.6}, {"low": 0.6}, {"low": 0.1}]) == 1
    assert controller_selection.pick([{"low": 0.3}] * 4) == 0
    both = controller_selection.candidates(5.75)
    assert both[0] == {"residual_cap": 0.01, "support_penalty": 5.75}
    assert both[1] == {"residual_cap": None, "support_penalty": 5.75}
    assert both[-1] == {"residual_cap": None, "support_penalty": None} and len(both) == 4
    # no noise measured: the cap and the paper's, no penalty candidate
    assert controller_selection.candidates(None) == both[2:]


def test_an_estimate_outside_the_returns_is_none_and_keeps_rule_2s_candidate():
    """FQE diverged on icu-sepsis-terminate's 1k log (26.7 [-60.8, 114.2] for survival in
    [0, 1]): such a candidate is never chosen; when it is the first, it is kept."""
    def e(estimate, low):
        return {"estimate": estimate, "low": low}

    span = (0.0, 1.0)
    assert controller_selection.pick([e(0.8, 0.7), e(26.7, 0.9), e(0.85, 0.75)], span) == 2
    assert controller_selection.pick([e(26.7, -60.8), e(0.32, 0.2), e(0.53, 0.47)], span) == 0
    assert controller_selection.pick([e(26.7, -60.8), e(0.32, 0.2), e(0.53, 0.47)]) == 2  # no span
    assert controller_selection.pick([e(0.5, 0.4), e(1.05, 0.95)], span) == 1  # within a tenth


def test_a_candidate_the_held_out_log_does_not_take_is_not_valued():
    """icu-sepsis's 50k plain file (10,000 held-out episodes): FQE valued the cap alone, whose
    median decision the held-out episodes took once in that state, at 0.888 [0.852, 0.923];
    its exact survival is 0.788, rule 2's candidate's (held out 33 times) 0.839."""
    def e(estimate, low, pairs):
        return {"estimate": estimate, "low": low, "pairs": pairs}

    seen = [e(0.8419, 0.8338, 33), e(0.8213, 0.7953, 18), e(0.8878, 0.8521, 1),
            e(0.8680, 0.8319, 1)]
    span = (0.0, 1.0)
    assert controller_selection.pick(seen, span) == 0
    assert controller_selection.pick([{k: v for k, v in c.items() if k != "pairs"} for c in seen],
                          span) == 2   # FQE alone takes the extrapolated one
    assert controller_selection.valued(seen, span)[2].startswith("fewer than 3")
    # rule 2's candidate unsupported: the log cannot weigh the others against it
    assert controller_selection.pick([e(0.80, 0.70, 2), e(0.85, 0.80, 40)], span) == 0
    assert controller_selection.pick([e(0.80, 0.70, 3), e(0.85, 0.80, 40)], span) == 1


def test_decisions_the_held_out_log_hardly_holds_come_off_the_bound():
    """A 10k plain file (FQE's seed 1): the penalty without the cap, a third of its decisions
    on pairs held out fewer than 3 times, 0.940 [0.895, 0.986] by FQE, exact 0.810; rule 2's
    candidate, 7% rare, 0.851 [0.823, 0.879], exact 0.814."""
    def e(low, pairs, rare):
        return {"estimate": low + 0.03, "low": low, "pairs": pairs, "rare": rare}

    seen = [e(0.8233, 11, 0.074), e(0.8949, 7, 0.329), e(0.7496, 0, 0.763)]
    span = (0.0, 1.0)
    assert controller_selection.bounds(seen, span) == pytest.approx([0.7493, 0.5659, -0.0134],
                                                                    abs=1e-12)
    assert controller_selection.pick(seen, span) == 0
    assert controller_selection.pick([{k: v for k, v in c.items() if k != "rare"} for c in seen],
                          span) == 1   # the interval alone takes the extrapolated one
    # the widening scales with the returns' range; no span, no widening
    assert controller_selection.bounds(seen, (0.0, 2.0))[1] == pytest.approx(0.8949 - 0.658,
                                                                             abs=1e-12)
    assert controller_selection.bounds(seen).tolist() == [c["low"] for c in seen]
    # a candidate far better where the log holds its decisions still wins
    assert controller_selection.pick([e(0.70, 20, 0.05), e(0.80, 20, 0.05)], span) == 1


def test_pair_counts_count_the_held_out_steps_of_each_decisions_state_and_action():
    obs = np.array([[0.0, 1.0], [0.0, 1.0], [2.0, 0.0], [0.0, 1.0], [2.0, 0.0]])
    logged = np.array([1, 1, 0, 2, 1])
    stay, other = controller_selection.pair_counts(obs, logged, 3,
                                                   [logged, np.array([2, 0, 2, 0, 0])])
    # state (0, 1) took action 1 twice and 2 once; state (2, 0) took 0 once and 1 once
    assert stay.tolist() == [2, 2, 1, 1, 1]
    assert other.tolist() == [1, 0, 0, 0, 1]


def test_each_candidate_decides_by_the_controllers_rule():
    # four actions at one step: the median residual 0.02 passes all, the cap (0.01 x p90 1)
    # only action 0; action 2 has the best value but one episode behind it
    parts = {"residual": np.array([[0.0, 0.02, 0.02, 0.02]]),
             "value": np.array([[0.0, 0.5, 1.0, 0.2]]),
             "support": np.array([[50.0, 50.0, 1.0, 50.0]]), "value_std": 1.0, "p90": 1.0}
    chosen = [int(c[0]) for c in
              controller_selection.decisions(parts, controller_selection.candidates(5.0))]
    # cap and penalty: 0; penalty: 1 (0.5 - 5/sqrt(50) beats 1 - 5); cap: 0; neither: 2
    assert chosen == [0, 1, 0, 2]


#: (at once, in blocks of 5) decompositions of the held-out steps made while ``icu`` trains
BLOCKED = []


@pytest.fixture(scope="module")
def icu(tmp_path_factory):
    """A plain-file icu-sepsis log (150 episodes, 30 held out) and its model trained once as
    ``aoc train`` trains it, the selection's FQE cut short (200 steps, 3 refits), and indexed;
    the progress labels it showed."""
    from tests.conftest import run_aoc

    root = tmp_path_factory.mktemp("select")
    data, _ = collect("icu-sepsis", episodes=150, seed=0)
    path = write_plain_npz(data, root / "icu.npz")
    code, _out, err = run_aoc("--store", str(root / "store"), "ingest", str(path), "--name",
                              "icu")
    assert code == 0, err
    steps, refits = controller_selection.FQE_STEPS, controller_selection.FQE_REFITS
    controller_selection.FQE_STEPS, controller_selection.FQE_REFITS = 200, 3
    labels = []
    original = controller_selection.decompositions

    def both(*args, **kwargs):      # every decomposition again, 5 distinct beliefs at once
        whole = original(*args, **kwargs)
        queries, controller_selection.QUERIES = controller_selection.QUERIES, 5
        try:
            BLOCKED.append((whole, original(*args, **kwargs)))
        finally:
            controller_selection.QUERIES = queries
        return whole
    controller_selection.decompositions = both
    try:
        trained = aoc_cli.train("icu", store=root / "store", threads=1, max_epochs=1, hidden=8,
                                progress=lambda done, total=None, label=None:
                                labels.append(label))
    finally:
        controller_selection.FQE_STEPS, controller_selection.FQE_REFITS = steps, refits
        controller_selection.decompositions = original
    aoc_cli.build_index("icu", store=root / "store")
    return root / "store", trained.metrics, labels


def test_train_chooses_the_controller_on_held_out_episodes(icu):
    store, metrics, labels = icu
    chosen = metrics["settings"]["controller_selection"]
    lows = [c["low"] for c in chosen["candidates"]]
    assert len(lows) == 4 and all(np.isfinite(lows))
    # the highest lower bound among the valued, rule 2's where it is not valued itself
    assert all(c["valued"] == (c["pairs"] >= controller_selection.MIN_PAIRS) for c in
               chosen["candidates"])
    ok = [c["valued"] for c in chosen["candidates"]]
    # the penalty candidates carry rule 2's measured bound (aoc_cli.training.evidence)
    measured = metrics["settings"]["support_penalty"]
    assert measured["value"] > 0 and measured["noise"] > 0
    tried = controller_selection.candidates(measured["value"])
    assert [c["settings"] for c in chosen["candidates"]] == list(tried)
    bounds = [c["bound"] for c in chosen["candidates"]]
    lo, hi = chosen["returns"]
    assert bounds == pytest.approx([c["low"] - c["rare"] * (hi - lo)
                                    for c in chosen["candidates"]], abs=1e-12)
    best = tried[0] if not ok[0] else tried[int(np.argmax(np.where(ok, bounds, -np.inf)))]
    assert chosen["chosen"] == best
    assert {k: metrics["controller"][k] for k in best} == best
    assert chosen["episodes"] == 30 and chosen["steps"] == metrics["val_rows"]
    why = {r["setting"]: r["why"] for r in metrics["settings"]["decided"]}
    assert why["residual_cap"].startswith("chosen among 4 controllers by the highest lower")
    assert why["support_penalty"].startswith("chosen with residual_cap, by the same rule")
    if best["support_penalty"] is not None:  # rule 2's measure stays with the penalty chosen
        assert "the penalty: a finite state the log revisits" in why["support_penalty"]
        decided = {r["setting"]: r for r in metrics["settings"]["decided"]}
        assert decided["support_penalty"]["noise"] == measured["noise"]
    assert any(label and label.startswith("choosing the controller: FQE") for label in labels)
    # the choice is saved with the model and every decision takes it, each flag over it
    own = aoc_cli.open_session("icu", store=store).controller.config
    assert (own.residual_cap, own.support_penalty) == (best["residual_cap"],
                                                        best["support_penalty"])
    flag = aoc_cli.open_session("icu", store=store, controller={"support_penalty": 1.0})
    assert flag.controller.config.support_penalty == 1.0


def test_the_held_out_decompositions_are_the_same_made_in_blocks(icu):
    assert BLOCKED
    for whole, blocked in BLOCKED:
        assert whole["distinct"] > 3 * 5                       # several blocks
        # the exchange's rounds run over a batch: a query's weights move within its precision
        for key in ("residual", "value", "support"):
            np.testing.assert_allclose(blocked[key], whole[key], rtol=1e-9, atol=1e-12)
        assert (blocked["p90"], blocked["distinct"]) == (whole["p90"], whole["distinct"])


def test_the_k_rule_is_saved_with_the_model_and_the_index_takes_it(icu):
    store, metrics, _ = icu
    config = json.loads((Store(store).corpus("icu").models_dir / "default" / "config.json")
                        .read_text())
    rule = 2 * (config["config"]["belief_dim"] + 1)  # the paper's, for a value model
    assert metrics["controller"]["k"] == config["metrics"]["controller"]["k"] == rule
    assert aoc_cli.open_session("icu", store=store).controller.k == rule


def test_a_setting_given_skips_the_choice_and_k_travels_with_the_model(icu, aoc):
    store = str(icu[0])
    # (--value return: the fitted Q evaluation of the values is not what this tests, and
    # costs a minute)
    code, out, err = aoc("--store", store, "train", "icu", "--model", "given",
                         "--support-penalty", "2", "--k", "7", "--value", "return",
                         "--threads", "1", "--epochs", "1", "--hidden", "8", "--format",
                         "json")
    assert code == 0, err
    metrics = json.loads(out)
    assert "controller_selection" not in metrics["settings"]
    # what was given, and rule 2's cap for the setting not given
    assert metrics["controller"] == {"support_penalty": 2.0, "residual_cap": 0.01, "k": 7,
                                     "do_no_harm": "off"}
    code, out, err = aoc("--store", store, "index", "icu", "--model", "given", "--format",
                         "json")
    assert code == 0, err
    assert json.loads(out)["k"] == 7
    session = aoc_cli.open_session("icu", model="given", store=store)
    assert session.controller.k == 7 and session.controller.config.support_penalty == 2.0
    over = aoc_cli.open_session("icu", model="given", store=store, controller={"k": 9})
    assert over.controller.k == 9


def test_train_refuses_a_controller_setting_it_does_not_save(icu, aoc):
    store = str(icu[0])
    code, _out, err = aoc("--store", store, "train", "icu", "--residual-cap", "0")
    assert code == 2 and err.strip().startswith("aoc: error:") and "--residual-cap" in err
    with pytest.raises(Exception, match="sampler"):
        aoc_cli.train("icu", store=store, controller={"sampler": "bc"})

