"""A built-in task's own training settings (``Task.training``, aoc_cli.belief.task_settings):
taken by ``aoc train`` for a corpus collected from the task, recorded in the model's config,
shown, overridden by a flag, skipped by --paper; an ingested corpus keeps the generic defaults."""

import json

import pytest

from aoc_cli.belief import task_settings
from aoc_cli.envs import TASKS, collect, collected_task
from aoc_cli.store import Store

QUICK = ["--threads", "1", "--epochs", "1", "--hidden", "8", "--format", "json"]


@pytest.fixture
def upright(store):
    s = Store(store)
    data, _ = collect("pendulum-het-upright", steps=2000, seed=0)
    s.write("up", data)
    ingested = collect("pendulum-het-upright", steps=2000, seed=0)[0]
    ingested.source = {"kind": "ingest", "file": "up.csv"}
    s.write("file", ingested)
    return s


def _saved(store, corpus, model):
    return json.loads((store.corpus(corpus).models_dir / model / "config.json").read_text())


def test_every_task_setting_is_an_optional_flag_of_aoc_train():
    import inspect

    from aoc_cli.cli.train import train

    params = inspect.signature(train).parameters
    for task in TASKS.values():
        assert set(task.training) <= set(task_settings.KEYS), task.name
        for values in task.training.values():
            assert set(values) <= set(task_settings.FIELDS), task.name
    for name in task_settings.FIELDS:  # None when not given: a task's value can fill it
        assert params[name].default is None or getattr(params[name].default, "default",
                                                       0) is None, name
    assert TASKS["pendulum-het-upright"].training == {"value": {"gamma": 0.9}}
    assert TASKS["pendulum-het"].training == {} and TASKS["maze"].training == {}


def test_the_collected_task_is_read_from_the_manifest(upright):
    assert upright.corpus("up").manifest["sources"][0]["task"] == "pendulum-het-upright"
    assert collected_task(upright.corpus("up")) == "pendulum-het-upright"
    assert collected_task(upright.corpus("file")) == ""
    assert task_settings.for_corpus(upright.corpus("up")) == ("pendulum-het-upright",
                                                              {"value": {"gamma": 0.9}})
    assert task_settings.for_corpus(upright.corpus("up"), paper=True)[1] == {}
    assert task_settings.for_corpus(upright.corpus("file")) == ("", {})


def test_a_corpus_of_mixed_sources_has_no_task_for_training_nor_control():
    """One rule for training and control: a corpus appended from a task and a file (or from two
    tasks) takes the defaults in both, never one task's settings in one and not the other."""
    from types import SimpleNamespace

    import importlib
    mixed = SimpleNamespace(manifest={"sources": [
        {"kind": "collect", "task": "pendulum-het-upright"}, {"kind": "ingest", "path": "x.npz"}]})
    two = SimpleNamespace(manifest={"sources": [
        {"kind": "collect", "task": "maze"}, {"kind": "collect", "task": "lunar"}]})
    one = SimpleNamespace(manifest={"sources": [
        {"kind": "collect", "task": "maze"}, {"kind": "collect", "task": "maze"}]})
    for entry in ("control", "evaluation", "explanation"):
        assert importlib.import_module(f"aoc_cli.api.{entry}").collected_task is collected_task
    assert [collected_task(c) for c in (mixed, two, one)] == ["", "", "maze"]


def test_aoc_train_takes_records_and_shows_the_tasks_gamma(aoc, upright):
    code, out, err = aoc("train", "up", *QUICK)
    assert code == 0, err
    metrics = json.loads(out)
    assert metrics["task_settings"] == {"task": "pendulum-het-upright",
                                        "settings": {"gamma": 0.9}}
    assert "pendulum-het-upright's own training settings: --gamma 0.9" in err
    saved = _saved(upright, "up", "default")
    assert saved["config"]["gamma"] == 0.9 and saved["value"]["gamma"] == 0.9
    assert saved["metrics"]["task_settings"]["settings"] == {"gamma": 0.9}


@pytest.mark.parametrize("args, gamma", [(["--gamma", "0.99"], 0.99), (["--paper"], 0.99),
                                         (["--belief", "dynamics"], 0.99)])
def test_a_flag_or_paper_overrides_the_tasks_setting(aoc, upright, args, gamma):
    code, out, err = aoc("train", "up", "--model", "m", *args, *QUICK)
    assert code == 0, err
    assert _saved(upright, "up", "m")["config"]["gamma"] == gamma
    assert json.loads(out).get("task_settings", {}).get("settings", {}) == {}
    assert "own training settings" not in err


def test_settings_apply_to_the_model_they_were_measured_with():
    settings = {"all": {"mode": "imitation"}, "value": {"gamma": 0.9}}
    assert task_settings.resolve({"mode": None, "gamma": None}, settings)[1] == {
        "mode": "imitation"}
    upright = {"value": {"gamma": 0.9}}
    for given, used in (({}, {"gamma": 0.9}), ({"belief": "critic"}, {}),
                        ({"dynamics_weight": 1.0}, {}), ({"mode": "imitation"}, {}),
                        ({"gamma": 0.5}, {})):
        assert task_settings.resolve(given, upright)[1] == used, given


def test_an_ingested_corpus_keeps_the_generic_defaults(aoc, upright):
    code, out, err = aoc("train", "file", *QUICK)
    assert code == 0, err
    assert _saved(upright, "file", "default")["config"]["gamma"] == 0.99
    assert "task_settings" not in json.loads(out)


def test_ward_trains_in_imitation_mode_by_default(aoc, store):
    s = Store(store)
    s.write("w", collect("ward", episodes=40, seed=0)[0])
    code, out, err = aoc("train", "w", "--history-length", "0", "--hidden", "8",
                         "--weight-decay", "0", "--threads", "1", "--epochs", "1",
                         "--format", "json")
    assert code == 0, err
    assert json.loads(out)["mode"] == "imitation" and "--mode imitation" in err
