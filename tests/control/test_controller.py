"""The accountable controller on small trained corpora: decisions, support, selection, OOD."""

import numpy as np
import pytest

from aoc_cli.control import ControllerConfig, HistoryBuffer, rollout
from aoc_cli.envs import make_env
from aoc_cli.cli.errors import message
from aoc_cli.errors import AocError
from aoc_cli.rows import row_selection
from aoc_cli.control import open_session

from tests.control.corpora import corridor_store, maze_store


@pytest.fixture(scope="module")
def maze(tmp_path_factory):
    return maze_store(tmp_path_factory.mktemp("maze")).corpus("maze")


@pytest.fixture(scope="module")
def corridor(tmp_path_factory):
    return corridor_store(tmp_path_factory.mktemp("corridor")).corpus("corridor")


def maze_session(corpus, **kw):
    config = ControllerConfig(**{"epsilon": 0.1, **kw})  # the maze's (aoc train decides it)
    return open_session(corpus, config=config, seed=0)


def test_maze_controller_reaches_the_goal_and_chains_the_experts(maze):
    session = maze_session(maze)
    results, summary = rollout(session, make_env("maze"), 8, seed=100, audit=None)
    assert summary["success_rate"] >= 0.6, summary
    # supporting rows: pi1/pi2 before the wall, pi3/pi4 after it (by weight), on all 8 episodes
    env = make_env("maze")
    from aoc_cli.control.episodes import run_episode

    episodes = [run_episode(env, session.controller, session.model.history_length, maze, 0,
                            100 + i, keep_decisions=True) for i in range(8)]
    codes, labels = maze.tag("policy")
    # every step of every successful episode: early = before x = 6; late = past x = 12, where
    # the 4-step history (at most 1 a step) lies entirely past the wall at x = 8
    early, late = [], []
    for res in (r for r in episodes if r.success):
        for obs, d in zip(res.observations, res.decisions):
            share = {lab: d.support_weights[codes[d.support_rows] == i].sum()
                     for i, lab in enumerate(labels)}
            (early if obs[0] < 6 else late if obs[0] > 12 else []).append(share)
    assert early and late
    assert np.mean([s["pi1"] + s["pi2"] for s in early]) > 0.8
    assert np.mean([s["pi3"] + s["pi4"] for s in late]) > 0.8


def test_decision_is_the_best_value_among_candidates_within_the_epsilon_quantile(maze):
    session = maze_session(maze, epsilon=0.3)
    h = HistoryBuffer(session.model.history_length, 2, 2, False).history()
    d = session.controller.decide(np.array([1.0, 1.0], np.float32), h)
    q = np.quantile(d.candidate_residuals, 0.3)
    assert np.array_equal(d.passed, d.candidate_residuals <= q + 1e-12 * max(1, q))
    assert d.passed[d.chosen]
    assert d.candidate_values[d.chosen] == d.candidate_values[d.passed].max()
    np.testing.assert_array_equal(d.action, d.candidates[d.chosen])
    # the record's figures are the decomposition's
    assert abs(d.support_weights.sum() - 1) < 1e-9
    values = session.index.values[d.support_rows]
    assert abs(values @ d.support_weights - d.value) < 1e-6


def test_epsilon_one_keeps_every_candidate(maze):
    session = maze_session(maze, epsilon=1.0)
    h = HistoryBuffer(session.model.history_length, 2, 2, False).history()
    d = session.controller.decide(np.array([2.0, 1.0], np.float32), h)
    assert d.passed.all() and d.candidate_values[d.chosen] == d.candidate_values.max()


def test_select_restricts_supporting_rows_to_the_tag(maze):
    selection = row_selection(maze, {"policy": ["pi1"]})
    session = open_session(maze, config=ControllerConfig(epsilon=0.1), selection=selection)
    results, _ = rollout(session, make_env("maze"), 1, seed=3, audit=None)
    codes, labels = maze.tag("policy")
    from aoc_cli.control.episodes import run_episode

    res = run_episode(make_env("maze"), session.controller, session.model.history_length, maze,
                      0, 5, keep_decisions=True)
    rows = np.concatenate([d.support_rows for d in res.decisions])
    assert len(rows) and set(codes[rows]) == {labels.index("pi1")}


def test_selection_that_leaves_no_rows_is_refused(maze):
    with pytest.raises(AocError, match="no rows"):
        row_selection(maze, {"policy": ["pi1"]}, {"policy": ["pi1"]})
    with pytest.raises(AocError, match="has no value"):
        row_selection(maze, {"policy": ["pi9"]})


def test_noise_injected_after_step_t_is_flagged_out_of_distribution(maze):
    session = maze_session(maze, ood_warmup=4)
    env = make_env("maze")
    calm, _ = rollout(session, env, 3, seed=40)
    noisy, _ = rollout(session, env, 3, seed=40, noise_after=4, noise_std=1.0)
    # the disturbed action of step 4 shows in the history of step 5: flagged within 3 steps
    assert all(any(r.ood[4:8]) for r in noisy), [np.flatnonzero(r.ood)[:5] for r in noisy]
    assert not any(any(r.ood[:8]) for r in calm), [np.flatnonzero(r.ood)[:5] for r in calm]


def test_imitation_decision_is_the_argmax_of_its_rows_weights_times_their_labels(corridor):
    from aoc_cli.belief.row_labels import ROW_SMOOTHING, row_labels

    session = open_session(corridor)
    plain = open_session(corridor, config=ControllerConfig(row_smoothing=0.0))
    assert session.model.mode == "imitation" and session.index.candidates == "per_action"
    assert session.controller.row_smoothing == ROW_SMOOTHING  # the default with these candidates
    actions, head = corridor.actions, session.model.head_weights
    buf = HistoryBuffer(session.model.history_length, 2, 1, True)
    agree = 0
    for x in np.linspace(0.2, 9.8, 25):
        obs = np.array([x, np.sin(x)], np.float32)
        d = session.controller.decide(obs, buf.history())
        rows = d.support_rows
        labels = row_labels(actions[rows], session.index.beliefs[rows], head, 2, ROW_SMOOTHING)
        assert np.allclose(d.support_labels, labels, rtol=0, atol=1e-12)
        assert np.allclose(d.scores, d.support_weights @ labels, rtol=0, atol=1e-12)
        assert int(d.action) == int(np.argmax(d.scores))
        agree += int(d.action) == int(x < 5)
        # lambda 0, the paper's score: each action's weight in the same subset
        p = plain.controller.decide(obs, buf.history())
        assert np.array_equal(p.support_rows, rows)
        totals = np.bincount(actions[rows], weights=p.support_weights, minlength=2)
        assert np.allclose(p.scores, totals, rtol=0, atol=1e-12)
        assert int(p.action) == int(np.argmax(totals))
    assert agree >= 22  # the expert's rule, recovered from the corpus


def test_a_logged_step_in_imitation_mode_is_the_decision_alone_without_its_episode(corridor):
    from aoc_cli.explanation import explain_logged_step

    session = open_session(corridor)
    for episode, step in [(3, 5), (20, 0), (41, 11)]:
        (rec,) = explain_logged_step(session, corridor, episode, step)
        row = int(corridor.episode_starts[episode]) + step
        assert rec["role"] == "decision" and rec["row"] == row
        assert rec["logged_action"] == int(corridor.actions[row])
        support = rec["support"]
        assert support and all(s["episode"] != episode for s in support)
        # the record shows each row's label; the scores are the sum of weight x label
        totals = np.sum([s["weight"] * np.asarray(s["label"]) for s in support], axis=0)
        assert np.allclose(rec["scores"], totals, rtol=0, atol=1e-12)
        assert rec["action"] == int(np.argmax(totals))
    assert session.controller.selection is None   # the left-out episode is not left behind


def test_residual_cap_keeps_candidates_under_c_times_the_typical_p90(maze):
    session = maze_session(maze, epsilon=0.5, residual_cap=2.0)
    p90 = session.index.meta["typical_residual"]["p90"]
    assert session.controller.residual_cap == pytest.approx(2.0 * p90)
    h = HistoryBuffer(session.model.history_length, 2, 2, False).history()
    d = session.controller.decide(np.array([0.0, 0.0], np.float32), h)
    r = d.candidate_residuals
    q = np.quantile(r, 0.5)
    expected = r <= min(q, 2.0 * p90) + 1e-12
    assert expected.sum() < (r <= q + 1e-12).sum()  # the cap bites at the start (uniform 2-d)
    assert np.array_equal(d.passed, expected)
    assert d.residual <= 2.0 * p90
    assert d.candidate_values[d.chosen] == d.candidate_values[d.passed].max()


def test_residual_cap_falls_back_to_the_smallest_residual_when_none_pass(maze):
    session = maze_session(maze, epsilon=0.5, residual_cap=1e-9)
    h = HistoryBuffer(session.model.history_length, 2, 2, False).history()
    d = session.controller.decide(np.array([3.0, 12.0], np.float32), h)  # off the data
    assert d.candidate_residuals.min() > session.controller.residual_cap  # nothing under it
    assert d.passed.sum() >= 1
    assert d.residual == d.candidate_residuals.min()
    assert np.all(d.candidate_residuals[d.passed] == d.candidate_residuals.min())


def test_residual_cap_must_be_positive():
    # the library names its parameter (the command line shows --residual-cap)
    with pytest.raises(AocError, match="^residual_cap must be > 0"):
        ControllerConfig(residual_cap=0.0)


def test_a_models_settings_under_the_flags_given():
    saved = {"epsilon": 0.1, "residual_cap": 0.01}
    own = ControllerConfig.for_model(saved)
    assert (own.epsilon, own.residual_cap) == (0.1, 0.01) and own.k is None
    # a flag given wins; a flag not given (None) leaves the model's setting
    assert ControllerConfig.for_model(saved, epsilon=0.3, k=None).epsilon == 0.3
    assert ControllerConfig.for_model(saved, k=None).k is None
    # a model with none recorded: the paper's defaults
    assert ControllerConfig.for_model(None) == ControllerConfig.for_model({}) == \
        ControllerConfig()
    with pytest.raises(AocError, match="^epsilon must be in") as err:
        ControllerConfig.for_model(saved, epsilon=2.0)
    # the library names its parameter; the command line shows the flag
    assert message(err.value).startswith("--epsilon must be in")
    with pytest.raises(AocError, match="^residual_cap must be > 0") as err:
        ControllerConfig(residual_cap=-1.0)
    assert message(err.value).startswith("--residual-cap must be > 0")


def test_the_typical_residual_has_one_typed_accessor(maze):
    from aoc_cli.index import TypicalResidual, load_index

    ci = open_session(maze).index
    recorded = ci.meta["typical_residual"]
    assert (ci.typical.p50, ci.typical.p90, ci.typical.p99) == \
        (recorded["p50"], recorded["p90"], recorded["p99"])
    assert ci.typical_residual == recorded["p50"] and ci.typical.sample == recorded["sample"]
    assert TypicalResidual.from_meta({}) == TypicalResidual(None, None, None, 0)
    # the model's hash is computed once, and is what a fresh load computes
    model = ci.model
    assert model.hash is model.hash and model.hash == load_index(maze).model.hash


def test_row_smoothing_given_to_a_value_model_is_a_warning_not_silence(maze):
    """lambda shapes ABC's scores only: given to a value-mode model it is said to be unused."""
    from aoc_cli.errors import AocWarning

    with pytest.warns(AocWarning, match="row_smoothing.*does not use it"):
        session = maze_session(maze, row_smoothing=0.5)
    assert session.model.mode == "value"
