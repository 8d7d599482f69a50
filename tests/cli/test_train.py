import json

import pytest

from aoc_cli.store import Store

from tests.belief.corpora import discrete_imitation, synthetic_value

QUICK = ["--threads", "1", "--epochs", "2", "--hidden", "16", "--format", "json"]


@pytest.fixture
def corpora(store):
    s = Store(store)
    s.write("syn", synthetic_value(episodes=10, length=20))
    s.write("free", discrete_imitation(episodes=10, length=20))
    s.write("one", synthetic_value(episodes=1, length=20))
    return s


def test_imitation_mode_on_a_reward_free_discrete_corpus_reports_accuracy(aoc, corpora):
    code, out, err = aoc("train", "free", "--mode", "imitation", *QUICK)
    assert code == 0, err
    metrics = json.loads(out)
    assert metrics["model"] == "default" and metrics["mode"] == "imitation"
    assert 0.0 <= metrics["val_accuracy"] <= 1.0 and "val_r2" not in metrics


@pytest.mark.parametrize("args, says", [
    (["free", "--mode", "value"], "no rewards.*--mode imitation"),
    (["syn", "--value", "nope"], "unknown --value 'nope'"),
    (["syn", "--history-length", "-1"], "--history-length must be >= 0"),
    (["one"], "1 episode.*at least 2"),
    (["syn", "--mode", "fancy"], "unknown --mode"),
    (["missing"], "no corpus 'missing'"),
])
def test_bad_input_exits_2_with_one_line(aoc, corpora, args, says):
    import re

    code, out, err = aoc("train", *args, *QUICK)
    assert code == 2 and out == ""
    lines = err.strip().splitlines()
    assert len(lines) == 1 and re.search(says, lines[0]), err


def test_train_prints_metrics_and_an_existing_model_needs_overwrite(aoc, corpora):
    code, out, err = aoc("train", "syn", "--value", "v", "--model", "m1", *QUICK)
    assert code == 0, err
    metrics = json.loads(out)
    assert metrics["model"] == "m1" and metrics["mode"] == "value" and metrics["epochs"] == 2
    assert {"train_loss", "val_loss", "val_r2", "seconds"} <= set(metrics)
    assert "val R^2" in err
    assert (corpora.corpus("syn").models_dir / "m1" / "weights.pt").is_file()
    code, _, err = aoc("train", "syn", "--value", "v", "--model", "m1", *QUICK)
    assert code == 2 and "already exists: pass --overwrite" in err
    code, out, err = aoc("train", "syn", "--value", "v", "--model", "m1", "--overwrite",
                         "--epochs", "1", "--threads", "1", "--hidden", "16", "--format", "csv")
    assert code == 0, err
    header, row = out.strip().splitlines()
    assert row.startswith("m1,value,1,")


@pytest.mark.parametrize("belief, extra", [("reward", []), ("critic", ["--critic-steps", "20"]),
                                           ("dynamics", [])])
def test_belief_kinds_train_from_the_cli_and_are_recorded(aoc, corpora, belief, extra):
    code, out, err = aoc("train", "syn", "--belief", belief, "--model", belief, *extra, *QUICK)
    assert code == 0, err
    metrics = json.loads(out)
    assert metrics["belief"] == belief and "val_r2" in metrics
    meta = json.loads((corpora.corpus("syn").models_dir / belief / "config.json").read_text())
    assert meta["config"]["belief"] == belief
    assert (meta["config"]["dynamics_weight"] > 0) == (belief == "dynamics")


@pytest.mark.parametrize("args, says", [
    (["--belief", "q"], "unknown --belief: 'q' is not one of 'value', 'critic'"),
    (["--belief", "critic", "--dynamics-weight", "1"], "--dynamics-weight belongs"),
    (["--belief", "reward", "--mode", "imitation"], "needs --mode value"),
])
def test_bad_belief_requests_exit_2(aoc, corpora, args, says):
    code, out, err = aoc("train", "syn", *args, *QUICK)
    assert code == 2 and out == "" and says in err and len(err.strip().splitlines()) == 1


def test_critic_steps_follow_the_data_and_epochs_with_the_estimate_shown_first(aoc, corpora):
    code, out, err = aoc("train", "syn", "--belief", "critic", "--model", "c", *QUICK)
    assert code == 0, err
    metrics = json.loads(out)
    per_epoch = -(-metrics["train_rows"] // 500)
    assert metrics["epochs"] == 2 * per_epoch and "2 epochs" in metrics["critic_steps_rule"]
    meta = json.loads((corpora.corpus("syn").models_dir / "c" / "config.json").read_text())
    assert meta["config"]["critic_steps"] == metrics["epochs"]  # resolved, not None
    said = " ".join(err.split())  # the console wraps long lines
    assert said.startswith(f"training the critic: {2 * per_epoch} gradient steps (2 epochs")
    assert " s at " in said.split("trained syn/c")[0]  # the estimate, before training ends


def test_device_is_a_training_setting_and_a_missing_gpu_is_refused_before_any_work(
        aoc_inproc, corpora, monkeypatch):
    """``--device cpu`` trains on the CPU and is recorded; ``--device cuda`` where torch sees no
    GPU is one line, exit 2, and no model folder (refused before the value targets)."""
    import torch

    code, out, err = aoc_inproc("train", "syn", "--value", "v", "--device", "cpu", *QUICK)
    assert code == 0, err
    assert json.loads(out)["device"] == "cpu"
    monkeypatch.setattr(torch.cuda, "is_available", lambda: False)
    code, out, err = aoc_inproc("train", "syn", "--value", "v", "--device", "cuda",
                                "--model", "g", *QUICK)
    assert code == 2 and out == ""
    assert err.strip().splitlines() == [
        "aoc: error: --device cuda asked for, but torch sees no GPU: use --device cpu"]
    assert not (corpora.corpus("syn").models_dir / "g").exists()
