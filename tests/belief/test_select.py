"""Settings chosen by validation on small corpora (aoc_cli.belief.select), reported and kept
in the model's config; the paper's settings by flag; the no-better-than-majority warning."""

import json

import numpy as np
import pytest

from aoc_cli.belief import select
from aoc_cli.envs import collect
from aoc_cli.store import Store

QUICK = ["--mode", "imitation", "--threads", "1", "--epochs", "3", "--format", "json"]


@pytest.fixture
def ward(store):
    s = Store(store)
    data, _ = collect("ward", episodes=200, seed=0)
    keep = np.arange(200) % 5 != 0
    s.write("ward", data.select_episodes(keep))
    s.write("held", data.select_episodes(~keep))
    return s


def test_open_settings_are_chosen_by_validation_and_recorded(aoc, ward):
    code, out, err = aoc("train", "ward", "--hidden", "32", *QUICK)
    assert code == 0, err
    metrics = json.loads(out)
    sel = metrics["selection"]
    assert sel["searched"] == ["history_length", "weight_decay"]
    tried = {(c["history_length"], c["weight_decay"]) for c in sel["candidates"]}
    assert {(0, 0.0), (1, 0.0), (4, 0.0)} <= tried and all(c["hidden"] == 32
                                                            for c in sel["candidates"])
    chosen = sel["chosen"]
    # the chosen history length has the lowest validation loss of the three, up to the margin
    by_l = {c["history_length"]: c["val_loss"] for c in sel["candidates"]
            if c["weight_decay"] == 0.0}
    assert by_l[chosen["history_length"]] <= min(by_l.values()) / (1 - select.MARGIN) + 1e-12
    assert "lowest validation loss" in sel["why"] and "chose history_length" in err
    config = json.loads((ward.corpus("ward").models_dir / "default" / "config.json").read_text())
    assert config["config"]["history_length"] == chosen["history_length"]
    assert config["config"]["hidden"] == 32
    assert config["metrics"]["selection"]["chosen"] == chosen


def test_given_settings_and_paper_flag_skip_the_search(aoc, ward):
    code, out, err = aoc("train", "ward", "--model", "p", "--paper", "--hidden", "16", *QUICK)
    assert code == 0, err
    metrics = json.loads(out)
    assert metrics["selection"]["searched"] == [] and "--paper" in metrics["selection"]["why"]
    config = json.loads((ward.corpus("ward").models_dir / "p" / "config.json").read_text())
    assert config["config"]["history_length"] == 4 and config["config"]["weight_decay"] == 0.0
    code, out, err = aoc("train", "ward", "--model", "g", "--history-length", "1", "--hidden",
                         "16", "--weight-decay", "0", *QUICK)
    assert code == 0, err
    assert "selection" not in json.loads(out)


def test_large_corpora_keep_the_paper_settings(ward):
    from aoc_cli.belief.config import BeliefConfig

    corpus = ward.corpus("ward")
    given = {"history_length": None, "hidden": None, "weight_decay": None}
    cfg = select.with_defaults(BeliefConfig(mode="imitation"), given)
    assert (cfg.history_length, cfg.hidden, cfg.weight_decay) == (4, 128, 0.0)
    assert select.open_settings(corpus, cfg, given) == ["history_length", "hidden",
                                                        "weight_decay"]
    old = select.SELECT_MAX_ROWS
    try:
        select.SELECT_MAX_ROWS = corpus.n_rows - 1
        assert select.open_settings(corpus, cfg, given) == []
        assert "over the" in select.why_no_search(corpus, cfg, given, False)
    finally:
        select.SELECT_MAX_ROWS = old
    assert select.open_settings(corpus, cfg, given, paper=True) == []


def test_no_better_than_majority_or_mean_is_said():
    assert "majority" in select.baseline_check({"val_accuracy": 0.93,
                                                "val_majority_accuracy": 0.93})
    assert select.baseline_check({"val_accuracy": 0.96, "val_majority_accuracy": 0.93}) is None
    assert "mean" in select.baseline_check({"val_r2": 0.001})
    assert select.baseline_check({"val_r2": 0.4}) is None


def test_default_training_on_ward_beats_the_majority_clearly(aoc, ward):
    code, out, err = aoc("train", "ward", "--mode", "imitation", "--threads", "1", "--epochs",
                         "8", "--format", "json")
    assert code == 0, err
    code, out, err = aoc("index", "ward", "--format", "json")
    assert code == 0, err
    code, out, err = aoc("evaluate", "ward", "--data", "held", "--baselines", "none",
                         "--format", "json")
    assert code == 0, err
    s = json.loads(out)
    assert s["accuracy"] >= s["majority_accuracy"] + 0.03, s
    assert s["auc"] >= 0.85 and s["support_max"] <= 21
