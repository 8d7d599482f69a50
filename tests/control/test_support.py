"""The support of a decision (distinct episodes behind its value) and the minimum-support rule."""

import numpy as np
import pytest

from aoc_cli.belief import BeliefConfig, train_model
from aoc_cli.control import ControllerConfig
from aoc_cli.control.support import penalised, row_episodes, support_episodes, support_filter
from aoc_cli.decompose import decompose
from aoc_cli.errors import AocError
from aoc_cli.control import open_session
from aoc_cli.index import build_index
from aoc_cli.store import (CorpusData, History, Store, box_space, discrete_space,
                           episode_starts_from_lengths)


def test_row_episodes_from_offsets():
    np.testing.assert_array_equal(row_episodes(np.array([0, 2, 3, 6])), [0, 0, 1, 2, 2, 2])


def test_a_repeated_point_is_backed_by_its_distinct_episodes():
    # rows 0-4 share one belief, from episodes 0, 0, 1, 2, 3 (4 distinct); rows 5-6 elsewhere
    beliefs = np.array([[0.0, 0.0]] * 5 + [[1.0, 0.0], [0.0, 1.0]])
    episode = np.array([0, 0, 1, 2, 3, 4, 5])
    dec = decompose(beliefs, np.array([[0.0, 0.0]]), k=7, values=np.zeros(7))
    support, counts = support_episodes(beliefs, dec.rows, dec.weights, dec.neighbours, episode)
    assert support[0] == 4.0
    assert counts[0][dec.rows[0] >= 0].tolist() == [4]


def test_a_hull_of_single_rows_has_kish_effective_size():
    # the query (0.25, 0.25) inside the triangle of three rows seen once each: weights 0.5,
    # 0.25, 0.25 give 1 / (0.25 + 0.0625 + 0.0625) = 8 / 3
    beliefs = np.array([[0.0, 0.0], [1.0, 0.0], [0.0, 1.0]])
    dec = decompose(beliefs, np.array([[0.25, 0.25]]), k=3, values=np.zeros(3))
    support, counts = support_episodes(beliefs, dec.rows, dec.weights, dec.neighbours,
                                       np.arange(3))
    assert support[0] == pytest.approx(8.0 / 3.0, rel=1e-9)
    assert sorted(counts[0].tolist()) == [1, 1, 1]


def test_vertices_backed_by_several_episodes_weigh_in_by_their_count():
    # vertex (0, 0) twice (episodes 0, 1), (1, 0) three times (episodes 2, 3, 4), (0, 1) once:
    # weights 0.5, 0.25, 0.25 give 1 / (0.25 / 2 + 0.0625 / 3 + 0.0625 / 1)
    beliefs = np.array([[0.0, 0.0]] * 2 + [[1.0, 0.0]] * 3 + [[0.0, 1.0]])
    dec = decompose(beliefs, np.array([[0.25, 0.25]]), k=6, values=np.zeros(6))
    support, _ = support_episodes(beliefs, dec.rows, dec.weights, dec.neighbours,
                                  np.arange(6))
    assert support[0] == pytest.approx(1.0 / (0.25 / 2 + 0.0625 / 3 + 0.0625), rel=1e-9)


def test_support_filter_keeps_supported_candidates_else_the_best_supported():
    passed = np.array([[True, True, False, True], [True, False, True, False]])
    support = np.array([[12.0, 3.0, 50.0, 10.0], [2.0, 40.0, 4.0, 1.0]])
    kept = support_filter(passed, support, 10)
    # step 1: 0 and 3 have >= 10 (2 has 50 but failed the residual filter); step 2: none has
    # 10 among those that pass, so the best supported of them (2, with 4)
    np.testing.assert_array_equal(kept, [[True, False, False, True],
                                         [False, False, True, False]])
    np.testing.assert_array_equal(support_filter(passed, support, None), passed)


def test_the_penalty_shrinks_values_by_the_episodes_behind_them():
    values, support = np.array([0.9, 0.7, 0.5]), np.array([1.0, 25.0, 0.5])
    # 0.9 - 2 x 0.1 / 1, 0.7 - 2 x 0.1 / 5, and a support under 1 counted as 1
    np.testing.assert_allclose(penalised(values, support, 2.0, 0.1), [0.7, 0.66, 0.3],
                               rtol=1e-12)
    assert penalised(values, support, None, 0.1) is values


def test_min_support_must_be_at_least_one_episode():
    with pytest.raises(AocError, match="min_support"):
        ControllerConfig(min_support=0.5)
    with pytest.raises(AocError, match="support_penalty"):
        ControllerConfig(support_penalty=-1.0)


def lucky_arm_data() -> CorpusData:
    """One state, one step an episode. Action 0: 30 episodes, reward 0.5; action 1: 1 episode,
    reward 1 (a lucky patient); action 2: 20 episodes, reward 0.6."""
    acts = [0] * 30 + [1] + [2] * 20
    rew = {0: 0.5, 1: 1.0, 2: 0.6}
    n = len(acts)
    return CorpusData(
        observations=np.ones((n, 2), np.float32), actions=np.array(acts),
        rewards=np.array([rew[a] for a in acts], np.float32), terminals=np.ones(n, bool),
        truncations=np.zeros(n, bool), episode_starts=episode_starts_from_lengths([1] * n),
        observation_space=box_space(2), action_space=discrete_space(3))


@pytest.fixture(scope="module")
def lucky(tmp_path_factory):
    store = Store(tmp_path_factory.mktemp("lucky"))
    corpus = store.write("lucky", lucky_arm_data())
    train_model(corpus, BeliefConfig(value="reward", history_length=0, seed=0, threads=1,
                                     max_epochs=200, patience=200), "default")
    build_index(corpus)
    return corpus


def test_min_support_passes_over_an_action_tried_by_one_patient(lucky):
    history = History(np.zeros((1, 0, 2), np.float32), np.zeros((1, 0), np.int64),
                      np.zeros((1, 0), np.float32), np.zeros((1, 0), bool))
    obs = np.ones(2, np.float32)
    plain = open_session(lucky, config=ControllerConfig(epsilon=1.0)).controller
    d = plain.decide(obs, history)
    # every action is logged in this state (residual 0): the paper's rule takes the lucky one;
    # its record has its support, the candidates' are computed only where a rule reads them
    assert int(d.action) == 1 and d.value == pytest.approx(1.0)
    assert d.support == pytest.approx(1.0, rel=1e-6) and len(d.candidate_support) == 0
    # a minimum of 1 episode passes every candidate (the support is at least 1)
    d = open_session(lucky, config=ControllerConfig(epsilon=1.0, min_support=1.0)
                     ).controller.decide(obs, history)
    assert int(d.action) == 1
    # (the query's belief is the rows' up to float32 rounding, so weights of ~1e-8 may fall
    # on a second vertex)
    np.testing.assert_allclose(d.candidate_support, [30, 1, 20], rtol=1e-6)
    assert d.support == pytest.approx(1.0, rel=1e-6)
    ruled = open_session(lucky, config=ControllerConfig(epsilon=1.0, min_support=10)).controller
    d = ruled.decide(obs, history)
    assert int(d.action) == 2 and d.value == pytest.approx(0.6)
    assert d.support == pytest.approx(20.0, rel=1e-6) and d.support_counts[0] == 20


def test_the_support_penalty_prefers_the_well_tried_action_to_the_lucky_one(lucky):
    history = History(np.zeros((1, 0, 2), np.float32), np.zeros((1, 0), np.int64),
                      np.zeros((1, 0), np.float32), np.zeros((1, 0), bool))
    obs = np.ones(2, np.float32)
    # corpus values' std 0.0801: 1 - z 0.0801 / 1 against 0.6 - z 0.0801 / sqrt(20) (and 0.5 -
    # z 0.0801 / sqrt(30)); z = 1 keeps the lucky action (0.920 > 0.582), z = 10 does not
    # (0.199 < 0.421)
    mild = open_session(lucky, config=ControllerConfig(epsilon=1.0, support_penalty=1.0))
    assert int(mild.controller.decide(obs, history).action) == 1
    strict = open_session(lucky, config=ControllerConfig(epsilon=1.0, support_penalty=10.0))
    d = strict.controller.decide(obs, history)
    assert int(d.action) == 2 and d.value == pytest.approx(0.6)  # the record keeps v_hat


def test_the_contrast_says_the_lucky_action_lost_to_the_penalty(lucky):
    from aoc_cli.explanation.contrast import contrast_record

    history = History(np.zeros((1, 0, 2), np.float32), np.zeros((1, 0), np.int64),
                      np.zeros((1, 0), np.float32), np.zeros((1, 0), bool))
    obs = np.ones(2, np.float32)
    session = open_session(lucky, config=ControllerConfig(epsilon=1.0, support_penalty=10.0))
    d = session.controller.decide(obs, history)
    rec = contrast_record(session.controller, obs, history, d, lucky, session.index)
    assert rec["candidate"] == 1 and rec["passed"]
    assert rec["why"]["reason"] == "lower penalised v_hat"
    assert rec["support_episodes"] == pytest.approx(1.0, rel=1e-6)
