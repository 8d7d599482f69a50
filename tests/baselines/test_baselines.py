"""The comparison controllers: features, nearest neighbours, bc, trivial policies, extras."""

from __future__ import annotations

import numpy as np
import pytest

from aoc_cli.baselines import (
    BASELINES,
    ActionSpace,
    MissingExtra,
    RawFeatures,
    extra_missing,
    make_baseline,
)
from aoc_cli.baselines.neighbours import NearestNeighbourController, knn_k
from aoc_cli.cli.errors import message
from aoc_cli.errors import AocError, ModelMissing
from tests.baselines.conftest import replay_history


def test_raw_features_at_control_time_equal_the_corpus_rows_own(pendulum):
    _root, corpus = pendulum
    f = RawFeatures.fit(corpus, history_length=4)
    table = f.corpus_features(corpus)
    assert table.shape == (corpus.n_rows, 3 + 1 + 4 * (3 + 1 + 2))
    # rows at an episode start (padding), inside one, and right after the start
    for row in (0, 1, 3, 57, int(corpus.episode_starts[1]) + 2):
        hist = replay_history(corpus, row, 4)
        x = f.transform(corpus.observations[row][None], corpus.actions[row][None], hist)
        np.testing.assert_allclose(x[0], table[row], rtol=1e-5, atol=1e-5)
    # standardised: the observation columns have mean 0, std 1 over the corpus
    np.testing.assert_allclose(table[:, :3].mean(0), 0, atol=1e-4)
    np.testing.assert_allclose(table[:, :3].std(0), 1, atol=1e-3)


def test_raw_features_zero_the_padding_and_mark_it_in_the_mask(pendulum):
    _root, corpus = pendulum
    f = RawFeatures.fit(corpus, history_length=4)
    x = f.corpus_features(corpus)[0]            # first row of the corpus: all padding
    steps = x[4:].reshape(4, 6)
    assert np.all(steps == 0)
    x2 = f.corpus_features(corpus)[2]           # two real steps, in the last two slots
    steps2 = x2[4:].reshape(4, 6)
    assert steps2[:, -1].tolist() == [0, 0, 1, 1]


def _brute_force(points: np.ndarray, query: np.ndarray, k: int) -> np.ndarray:
    d = ((points.astype(np.float64) - query.astype(np.float64)) ** 2).sum(1)
    return np.argsort(d, kind="stable")[:k]


@pytest.mark.parametrize("space", ["raw", "belief"])
def test_neighbour_values_are_the_mean_value_of_the_true_nearest_rows(session, space, rng):
    s, env = session
    k = knn_k(s)
    ctl = NearestNeighbourController(s, env, k=k, space=space)
    corpus = s.corpus
    row = 321
    hist = replay_history(corpus, row, s.model.history_length)
    cands = rng.uniform(-2, 2, size=(7, 1))
    value, rows = ctl.estimate(corpus.observations[row], cands, hist)
    points = ctl.features.corpus_features(corpus) if space == "raw" else np.asarray(s.index.beliefs)
    queries = ctl.embed(corpus.observations[row], cands, hist)
    for i in range(len(cands)):
        expect = _brute_force(points, queries[i], k)
        assert set(rows[i].tolist()) == set(expect.tolist())
        assert value[i] == pytest.approx(ctl.values[expect].mean(), rel=1e-9)


def test_1nn_of_a_corpus_rows_own_action_is_that_row(session):
    s, env = session
    ctl = make_baseline("1nn", s, env)
    corpus = s.corpus
    for row in (5, 400, 1500):
        hist = replay_history(corpus, row, s.model.history_length)
        value, rows = ctl.estimate(corpus.observations[row], corpus.actions[row][None], hist)
        assert rows[0, 0] == row
        assert value[0] == pytest.approx(ctl.values[row])


def test_nearest_neighbour_control_is_the_argmax_over_the_same_candidates(session):
    s, env = session
    ctl = make_baseline("knn", s, env, seed=11)
    hist = replay_history(s.corpus, 700, s.model.history_length)
    obs = s.corpus.observations[700]
    action = ctl.decide(obs, hist)
    cands = ActionSpace(s, env).candidates(np.random.default_rng(11), s.controller.config.candidates)
    value, _ = ctl.estimate(obs, cands, hist)
    np.testing.assert_allclose(action, cands[int(np.argmax(value))])
    assert len(cands) == 100 and np.all(np.abs(cands) <= 2)


def test_neighbours_honour_the_row_selection(pendulum):
    from aoc_cli.experiments.common import session as make_session
    from aoc_cli.control import ControllerConfig
    from aoc_cli.control import open_session
    from aoc_cli.envs import make_env
    from aoc_cli.rows import row_selection

    _root, corpus = pendulum
    env = make_env("pendulum-het")
    sel = row_selection(corpus, {"system": ["normal"]})
    s = open_session(corpus, "default", "default", ControllerConfig(), sel, 0)
    for name in ("knn", "knn-belief"):
        ctl = make_baseline(name, s, env)
        _v, rows = ctl.estimate(corpus.observations[10], np.linspace(-2, 2, 9)[:, None],
                                replay_history(corpus, 10, s.model.history_length))
        codes, labels = corpus.tag("system")
        assert set(codes[rows.ravel()].tolist()) == {labels.index("normal")}
    assert make_session(corpus, env).controller.selection is None


def test_zero_is_the_neutral_action_and_random_stays_in_the_box(session):
    s, env = session
    hist = replay_history(s.corpus, 0, s.model.history_length)
    zero = make_baseline("zero", s, env)
    np.testing.assert_array_equal(zero.decide(np.zeros(3), hist), [0.0])
    rnd = make_baseline("random", s, env, seed=4)
    rnd.reset()
    first = np.array([rnd.decide(np.zeros(3), hist) for _ in range(50)])
    assert first.min() >= -2 and first.max() <= 2 and first.std() > 0.5
    rnd2 = make_baseline("random", s, env, seed=4)
    rnd2.reset()
    again = np.array([rnd2.decide(np.zeros(3), hist) for _ in range(50)])
    np.testing.assert_array_equal(first, again)


def test_the_neutral_action_of_a_box_without_zero_is_its_centre():
    space = ActionSpace.__new__(ActionSpace)
    space.discrete, space.dim = False, 2
    space.low, space.high = np.array([1.0, -1.0]), np.array([3.0, 1.0])
    np.testing.assert_array_equal(space.neutral(), [2.0, 0.0])
    space.discrete = True
    assert space.neutral() == 0


def test_bc_acts_as_the_imitation_model_predicts(session):
    from aoc_cli.belief import load_model

    s, env = session
    bc = make_baseline("bc", s, env)
    model = load_model(s.corpus, "bc")
    hist = replay_history(s.corpus, 250, s.model.history_length)
    obs = s.corpus.observations[250]
    expect = np.clip(model.predict(obs[None], None, hist)[0], -2, 2)
    np.testing.assert_allclose(bc.decide(obs, hist), expect)


def test_bc_without_an_imitation_model_says_how_to_train_one(pendulum, tmp_path):
    from aoc_cli.experiments.common import session as make_session
    from aoc_cli.envs import make_env

    _root, corpus = pendulum
    env = make_env("pendulum-het")
    s = make_session(corpus, env)
    with pytest.raises(ModelMissing, match="needs an imitation-mode model 'nobc'") as err:
        make_baseline("bc", s, env, model_id="nobc")
    assert (err.value.model, err.value.mode) == ("nobc", "imitation")
    assert message(err.value).endswith(
        f": run `aoc train {corpus.name} --model nobc --mode imitation`")
    with pytest.raises(AocError, match="value-mode model") as err:
        make_baseline("bc", s, env, model_id="default")
    assert message(err.value).endswith(
        f"`aoc train {corpus.name} --model default --mode imitation --overwrite`")


def test_an_unknown_policy_lists_the_baselines(session):
    s, env = session
    with pytest.raises(AocError, match="knn-belief"):
        make_baseline("knn2", s, env)
    assert set(BASELINES) >= {"zero", "random", "1nn", "knn", "1nn-belief", "knn-belief", "bc",
                              "td3bc", "cql", "mpc"}


def test_a_missing_optional_package_says_pip_install_bench(monkeypatch):
    import importlib

    from aoc_cli.baselines.common import require

    real = importlib.import_module

    def fake(name, *a, **k):
        if name == "d3rlpy":
            raise ImportError("No module named 'd3rlpy'")
        return real(name, *a, **k)

    monkeypatch.setattr(importlib, "import_module", fake)
    with pytest.raises(MissingExtra, match=r"pip install -e \.\[bench\]"):
        require("d3rlpy", "td3bc")
    real_find = importlib.util.find_spec
    monkeypatch.setattr(importlib.util, "find_spec",
                        lambda n, *a: None if n == "pytorch_mppi" else real_find(n, *a))
    assert extra_missing("mpc") == "pytorch_mppi" and extra_missing("knn") is None
