import csv
import json

import numpy as np
import pytest
import torch

from aoc_cli.belief import BeliefConfig, load_model, train_model
from aoc_cli.belief.targets import value_targets
from aoc_cli.errors import AocError, ModelExists, ModelMissing, ModelStale
from aoc_cli.store import Store, seal

from tests.belief.corpora import (continuous_imitation, discrete_imitation, history_dependent,
                                  synthetic_value)

#: Small and quick: 64 hidden units, at most 15 epochs, one thread.
FAST = dict(threads=1, max_epochs=15, patience=5, batch_size=250, hidden=64)


def _across_batches(model) -> float:
    """The tolerance between beliefs of the same rows computed in batches of other shapes:
    a few float32 ulp on the CPU; on a GPU the kernels differ with the batch's shape (4e-5
    measured on an H100)."""
    return 1e-5 if model.device.type == "cpu" else 1e-4


@pytest.fixture(scope="module")
def value_run(tmp_path_factory):
    """One value-mode model on a corpus where v is a known function of (o, a)."""
    corpus = Store(tmp_path_factory.mktemp("store")).write("syn", synthetic_value())
    metrics = train_model(corpus, BeliefConfig(value="v", **FAST), "m")
    return corpus, metrics


def test_value_mode_learns_a_known_function_of_observation_and_action(value_run):
    corpus, metrics = value_run
    assert metrics["mode"] == "value" and metrics["val_r2"] > 0.9
    assert metrics["val_rows"] + metrics["train_rows"] == corpus.n_rows
    assert 1 <= metrics["best_epoch"] <= metrics["epochs"] <= FAST["max_epochs"]


def test_model_folder_holds_weights_config_metrics_and_values(value_run):
    corpus, metrics = value_run
    folder = corpus.models_dir / "m"
    state = torch.load(folder / "weights.pt", weights_only=True)
    assert "head.weight" in state and state["head.weight"].shape == (1, 20)
    meta = json.loads((folder / "config.json").read_text())
    assert meta["corpus_hash"] == corpus.hash and meta["corpus"] == "syn"
    assert meta["mode"] == "value" and meta["value"]["target"] == "v"
    assert meta["config"]["history_length"] == 4 and meta["dims"]["observation"] == 3
    assert len(meta["normalisation"]["observation_mean"]) == 3
    with open(folder / "metrics.csv") as f:
        rows = list(csv.DictReader(f))
    assert len(rows) == metrics["epochs"] and {"train_loss", "val_loss", "val_r2"} <= set(rows[0])
    values = np.load(folder / "values.npy", allow_pickle=False)
    assert values.dtype == np.float64
    np.testing.assert_array_equal(values, value_targets(corpus, "v", 0.99))


def test_loaded_model_beliefs_agree_across_entry_points(value_run):
    corpus, _ = value_run
    model = load_model(corpus)
    assert model.mode == "value" and model.d_b == 20 and model.history_length == 4
    rows = np.arange(0, corpus.n_rows, 7)
    beliefs = model.row_beliefs(corpus)[rows]
    hist = corpus.history(rows, 4)
    direct = model.beliefs(corpus.observations[rows], corpus.actions[rows], hist)
    assert direct.shape == (len(rows), 20) and direct.dtype == np.float32
    np.testing.assert_allclose(direct, beliefs, atol=_across_batches(model))
    # the head in original units reproduces predict(), which tracks the known value
    weight, bias = model.head_weights
    pred = model.predict(corpus.observations[rows], corpus.actions[rows], hist)
    np.testing.assert_allclose(beliefs.astype(np.float64) @ weight.T[:, 0] + bias[0], pred,
                               rtol=1e-4, atol=1e-4)
    assert np.corrcoef(pred, model.values[rows])[0, 1] > 0.9
    # one observation and history broadcast against K candidate actions
    cand = np.linspace(-1, 1, 5)[:, None]
    one = model.beliefs(corpus.observations[rows[:1]], cand, corpus.history(rows[:1], 4))
    tiled = model.beliefs(np.repeat(corpus.observations[rows[:1]], 5, 0), cand,
                          corpus.history(np.repeat(rows[:1], 5), 4))
    np.testing.assert_allclose(one, tiled, atol=1e-6)


def test_model_hash_identifies_weights_and_config(value_run):
    corpus, _ = value_run
    a, b = load_model(corpus, "m"), load_model(corpus, "m")
    assert a.hash == b.hash
    # the hash is computed once per loaded model (inference never changes the weights): a
    # model whose weights differ before its hash is first read has another hash
    c = load_model(corpus, "m")
    with torch.no_grad():
        c.net.head.bias += 1.0
    assert c.hash != a.hash
    # and a model whose weights change after its hash was read is hashed again
    with torch.no_grad():
        b.net.head.bias += 1.0
    assert b.hash == c.hash != a.hash


def test_same_seed_same_weights_other_seed_other_weights(tmp_path):
    corpus = Store(tmp_path).write("c", synthetic_value(episodes=10, length=20))
    cfg = dict(value="v", threads=1, max_epochs=3, patience=3, hidden=32, seed=5)
    train_model(corpus, BeliefConfig(**cfg), "a")
    train_model(corpus, BeliefConfig(**cfg), "b")
    train_model(corpus, BeliefConfig(**{**cfg, "seed": 6}), "c")
    wa, wb, wc = (torch.load(corpus.models_dir / m / "weights.pt", weights_only=True)
                  for m in "abc")
    assert all(torch.equal(wa[k], wb[k]) for k in wa)
    assert not torch.equal(wa["fc1.weight"], wc["fc1.weight"])


def test_history_is_used_when_the_value_depends_on_the_previous_action(tmp_path):
    corpus = Store(tmp_path).write("h", history_dependent())
    with_history = train_model(corpus, BeliefConfig(value="reward", history_length=2, **FAST), "h2")
    without = train_model(corpus, BeliefConfig(value="reward", history_length=0, **FAST), "h0")
    assert with_history["val_r2"] > 0.95
    assert without["val_r2"] < 0.1
    # L = 0: the belief depends on (o, a) only, and no history is needed to compute it
    model = load_model(corpus, "h0")
    b = model.beliefs(corpus.observations[:4], corpus.actions[:4], None)
    np.testing.assert_allclose(b, model.row_beliefs(corpus)[:4], atol=1e-6)


def test_imitation_on_discrete_actions_beats_the_majority_class(tmp_path):
    corpus = Store(tmp_path).write("d", discrete_imitation())
    metrics = train_model(corpus, BeliefConfig(mode="imitation", **FAST), "abc")
    assert metrics["val_majority_accuracy"] < 0.6
    assert metrics["val_accuracy"] > metrics["val_majority_accuracy"] + 0.3
    model = load_model(corpus, "abc")
    assert model.values is None and model.mode == "imitation"
    rows = np.arange(50)
    logits = model.predict(corpus.observations[rows], None, corpus.history(rows, 4))
    assert logits.shape == (50, 3)
    assert np.mean(logits.argmax(1) == corpus.actions[rows]) > 0.8
    assert not (corpus.models_dir / "abc" / "values.npy").exists()


def test_imitation_on_continuous_actions_predicts_them_in_original_units(tmp_path):
    corpus = Store(tmp_path).write("c", continuous_imitation())
    metrics = train_model(corpus, BeliefConfig(mode="imitation", **FAST), "abc")
    assert metrics["val_r2"] > 0.9
    model = load_model(corpus)
    rows = np.arange(100)
    pred = model.predict(corpus.observations[rows], None, corpus.history(rows, 4))
    assert pred.shape == (100, 2)
    assert np.abs(pred - corpus.actions[rows]).mean() < 0.1
    weight, bias = model.head_weights
    b = model.row_beliefs(corpus)[rows]
    np.testing.assert_allclose(b @ weight.T + bias, pred, atol=10 * _across_batches(model))


def test_bad_requests_are_refused_with_what_to_do(tmp_path):
    store = Store(tmp_path)
    corpus = store.write("c", synthetic_value(episodes=4, length=10))
    with pytest.raises(AocError, match="history_length must be >= 0"):
        train_model(corpus, BeliefConfig(value="v", history_length=-1), "x")
    one = store.write("one", synthetic_value(episodes=1, length=10))
    with pytest.raises(AocError, match="1 episode.*at least 2"):
        train_model(one, BeliefConfig(value="v", threads=1), "x")
    with pytest.raises(ModelMissing, match="has no trained model") as err:
        load_model(corpus)
    assert (err.value.corpus, err.value.model) == ("c", None)
    train_model(corpus, BeliefConfig(value="v", threads=1, max_epochs=1), "x")
    with pytest.raises(ModelExists, match="already exists: pass overwrite=True"):
        train_model(corpus, BeliefConfig(value="v", threads=1, max_epochs=1), "x")
    train_model(corpus, BeliefConfig(value="v", threads=1, max_epochs=2), "x", overwrite=True)
    assert load_model(corpus, "x").meta["metrics"]["epochs"] == 2
    assert load_model(corpus).id == "x"            # the only model
    train_model(corpus, BeliefConfig(value="v", threads=1, max_epochs=1), "default")
    train_model(corpus, BeliefConfig(value="v", threads=1, max_epochs=1), "z")
    assert load_model(corpus).id == "default"      # "default" before the latest
    with pytest.raises(AocError, match="has no model 'y'"):
        load_model(corpus, "y")


def test_a_model_of_a_changed_corpus_is_refused(tmp_path):
    store = Store(tmp_path)
    corpus = store.write("c", synthetic_value(episodes=4, length=10))
    train_model(corpus, BeliefConfig(value="v", threads=1, max_epochs=1), "m")
    changed = store.write("c", synthetic_value(episodes=2, length=10, seed=1), append=True)
    with pytest.raises(ModelStale, match=r"different version") as err:
        load_model(changed, "m")
    assert (err.value.model, err.value.built_from, err.value.found) == \
        ("m", corpus.hash, changed.hash)
    with pytest.raises(AocError, match="different version"):
        load_model(corpus, "m").row_beliefs(changed)


def test_a_model_trained_on_a_gpu_loads_where_torch_sees_none(tmp_path, monkeypatch):
    """The training device is recorded in the config but does not bind the model: a model
    trained with device "cuda" is loaded on the CPU of a machine without a GPU (weights are
    read with map_location="cpu")."""
    corpus = Store(tmp_path).write("c", synthetic_value(episodes=6, length=20))
    train_model(corpus, BeliefConfig(value="v", threads=1, max_epochs=1, hidden=16), "g")
    path = corpus.models_dir / "g" / "config.json"
    meta = json.loads(path.read_text())
    meta["config"]["device"] = "cuda"
    meta.pop("sha256", None)
    path.write_text(json.dumps(seal(meta)))
    monkeypatch.setattr(torch.cuda, "is_available", lambda: False)
    model = load_model(corpus, "g")
    assert model.device.type == "cpu" and model.config.device == "cuda"
    with pytest.raises(AocError, match="sees no GPU"):
        load_model(corpus, "g", device="cuda")
