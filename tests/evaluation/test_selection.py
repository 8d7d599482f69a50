"""The controller chosen on held-out episodes (aoc_cli.evaluation.selection, rule 6 of
docs/design.md "Settings from the log's evidence"): each candidate decides by the controller's
own rule, the rule takes the highest lower bound (ties: the more conservative), ``aoc train``
records what it chose and why, a setting given or --no-select skips it; the k saved with the
model reaches the index and every decision unless --k is given."""

import json

import numpy as np
import pytest

import aoc_cli
from aoc_cli.envs import collect
from aoc_cli.evaluation import selection
from aoc_cli.store import Store
from tests.plain_log import write_plain_npz


def test_the_rule_takes_the_highest_lower_bound_and_the_first_of_equals():
    assert selection.pick([{"low": 0.5}, {"low": 0.6}, {"low": 0.6}, {"low": 0.1}]) == 1
    assert selection.pick([{"low": 0.3}] * 4) == 0
    assert selection.CANDIDATES[0] == {"residual_cap": 0.01, "support_penalty": 5.0}
    assert selection.CANDIDATES[-1] == {"residual_cap": None, "support_penalty": None}


def test_each_candidate_decides_by_the_controllers_rule():
    # four actions at one step: the median residual 0.02 passes all, the cap (0.01 x p90 1)
    # only action 0; action 2 has the best value but one episode behind it
    parts = {"residual": np.array([[0.0, 0.02, 0.02, 0.02]]),
             "value": np.array([[0.0, 0.5, 1.0, 0.2]]),
             "support": np.array([[50.0, 50.0, 1.0, 50.0]]), "value_std": 1.0, "p90": 1.0}
    chosen = [int(c[0]) for c in selection.decisions(parts)]
    # cap and penalty: 0; penalty: 1 (0.5 - 5/sqrt(50) beats 1 - 5); cap: 0; neither: 2
    assert chosen == [0, 1, 0, 2]


@pytest.fixture
def icu(store, tmp_path):
    from tests.conftest import run_aoc

    data, _ = collect("icu-sepsis", episodes=300, seed=0)
    path = write_plain_npz(data, tmp_path / "icu.npz")
    code, _out, err = run_aoc("ingest", str(path), "--name", "icu")
    assert code == 0, err
    return Store(store)


QUICK = dict(threads=1, max_epochs=1, hidden=8)


def test_train_chooses_the_controller_on_held_out_episodes(icu, store, monkeypatch):
    monkeypatch.setattr(selection, "FQE_STEPS", 200)
    monkeypatch.setattr(selection, "FQE_REFITS", 3)
    labels = []
    trained = aoc_cli.train("icu", store=store, **QUICK,
                            progress=lambda done, total=None, label=None: labels.append(label))
    metrics = trained.metrics
    chosen = metrics["settings"]["controller_selection"]
    lows = [c["low"] for c in chosen["candidates"]]
    assert len(lows) == 4 and all(np.isfinite(lows))
    best = selection.CANDIDATES[int(np.argmax(lows))]
    assert chosen["chosen"] == best
    assert {k: metrics["controller"][k] for k in best} == best
    assert chosen["episodes"] == 60 and chosen["steps"] == metrics["val_rows"]
    why = {r["setting"]: r["why"] for r in metrics["settings"]["decided"]}
    assert why["support_penalty"].startswith("chosen among 4 controllers by the highest lower")
    assert any(label and label.startswith("choosing the controller: FQE") for label in labels)
    # the choice is saved with the model and every decision takes it
    aoc_cli.build_index("icu", store=store)
    own = aoc_cli.open_session("icu", store=store).controller.config
    assert (own.residual_cap, own.support_penalty) == (best["residual_cap"],
                                                        best["support_penalty"])


@pytest.mark.parametrize("given, no_select", [({"support_penalty": 2.0}, False), ({}, True)])
def test_a_setting_given_or_no_select_skips_the_choice(icu, store, given, no_select):
    metrics = aoc_cli.train("icu", store=store, **QUICK, controller=given,
                            no_select=no_select).metrics
    assert "controller_selection" not in metrics["settings"]
    expected = {"residual_cap": 0.01, "support_penalty": 5.0, **given}
    assert {k: metrics["controller"][k] for k in expected} == expected


def test_the_k_saved_with_the_model_reaches_every_decision(icu, store, aoc):
    code, out, err = aoc("train", "icu", "--no-select", "--k", "7", "--threads", "1",
                         "--epochs", "1", "--hidden", "8", "--format", "json")
    assert code == 0, err
    assert json.loads(out)["controller"]["k"] == 7
    code, out, err = aoc("index", "icu", "--format", "json")
    assert code == 0, err
    assert json.loads(out)["k"] == 7
    assert aoc_cli.open_session("icu", store=store).controller.k == 7
    assert aoc_cli.open_session("icu", store=store, controller={"k": 9}).controller.k == 9
    # without --k: the k rule's (the paper's 2 (d_b + 1) for a value model), saved and used
    metrics = aoc_cli.train("icu", store=store, **QUICK, no_select=True,
                            overwrite=True).metrics
    d_b = icu.corpus("icu").models_dir / "default" / "config.json"
    rule = 2 * (json.loads(d_b.read_text())["config"]["belief_dim"] + 1)
    assert metrics["controller"]["k"] == rule
    aoc_cli.build_index("icu", store=store)
    assert aoc_cli.open_session("icu", store=store).controller.k == rule


def test_train_refuses_a_controller_setting_it_does_not_save(icu, store, aoc):
    code, _out, err = aoc("train", "icu", "--residual-cap", "0", "--epochs", "1")
    assert code == 2 and err.strip().startswith("aoc: error:") and "--residual-cap" in err
    with pytest.raises(Exception, match="sampler"):
        aoc_cli.train("icu", store=store, controller={"sampler": "bc"})
