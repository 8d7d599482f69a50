"""aoc bench icu-sepsis: the policies learnt from a log, their exact values, the outputs."""

import json

import numpy as np
import pytest

from aoc_cli.baselines import sepsis_policies as sp
from aoc_cli.experiments.sepsis import run_sepsis
from aoc_cli.envs import icu_sepsis
from aoc_cli.cli.errors import message
from aoc_cli.errors import AocError, BadSetting


@pytest.fixture(scope="module")
def tables():
    return icu_sepsis.tables("mean")


def test_log_model_counts_a_hand_made_log():
    """Three episodes: (s3 a1 -> s4 a2 -> survival), (s3 a1 -> death), (s4 a0, truncated)."""
    states = np.array([3, 4, 3, 4])
    actions = np.array([1, 2, 1, 0])
    rewards = np.array([0.0, 1.0, 0.0, 0.0])
    terminals = np.array([False, True, True, False])
    starts = np.array([0, 2, 3, 4])
    model, behaviour, counts = sp.log_model(states, actions, rewards, terminals, starts)
    assert counts[3, 1] == 2 and counts[4, 2] == 1 and counts[4, 0] == 0  # truncated: left out
    np.testing.assert_allclose(model.P[3, 1, [4, icu_sepsis.STATE_DEATH]], [0.5, 0.5])
    assert model.P[4, 2, icu_sepsis.STATE_SURVIVAL] == 1.0 and model.r[4, 2] == 1.0
    np.testing.assert_allclose(model.d0[[3, 4]], [2 / 3, 1 / 3])
    np.testing.assert_allclose(behaviour[3, 1], 1.0)
    assert model.terminal[0] and not model.terminal[3]
    # by hand: V(4) = 1 under the behaviour, V(3) = 0.5 V(4) = 0.5, start 2/3 * 0.5 + 1/3 * 1
    assert model.value(behaviour) == pytest.approx(2 / 3, abs=1e-12)


def test_tabular_policy_without_enough_counts_is_the_logged_modal_action():
    states = np.array([3, 4, 3, 4, 3])
    actions = np.array([1, 2, 7, 2, 1])
    rewards = np.array([0.0, 1.0, 0.0, 1.0, 0.0])
    terminals = np.array([False, True, False, True, True])
    starts = np.array([0, 2, 4, 5])
    pol = sp.tabular_policy(states, actions, rewards, terminals, starts, min_count=10)
    assert pol[3] == 1 and pol[4] == 2
    # with min_count 1, the action with the higher Q: a7 leads to s4 (survival), a1 half dies
    pol = sp.tabular_policy(states, actions, rewards, terminals, starts, min_count=1)
    assert pol[3] == 7


def test_spibb_copies_the_behaviour_where_it_bootstraps_and_improves_elsewhere():
    """The hand-made log above: in s3, a1 (twice, half die) and a7 (once, to s4, survives)."""
    from aoc_cli.baselines.spibb import _model, spibb

    states = np.array([3, 4, 3, 4, 3])
    actions = np.array([1, 2, 7, 2, 1])
    rewards = np.array([0.0, 1.0, 0.0, 1.0, 0.0])
    terminals = np.array([False, True, False, True, True])
    starts = np.array([0, 2, 4, 5])
    model, behaviour, counts = _model(states, actions, rewards, terminals, starts)
    # every pair bootstrapped (N_wedge 10): the behaviour itself, unvisited states on action 0
    pi = spibb(model, behaviour, counts, 10, 0)
    np.testing.assert_array_equal(pi[[3, 4]], behaviour[[3, 4]])
    assert pi[0, 0] == 1.0 and model.terminal[0]
    # a1 trusted (2 >= 2), a7 not: a7 keeps its 1/3, a1 takes the rest (the only trusted one)
    pi = spibb(model, behaviour, counts, 2, 0)
    np.testing.assert_allclose(pi[3, [1, 7]], [2 / 3, 1 / 3], rtol=0, atol=1e-15)
    # nothing bootstrapped (N_wedge 1): all of s3's mass on the better a7
    pi = spibb(model, behaviour, counts, 1, 0)
    assert pi[3, 7] == 1.0


def test_bc_takes_the_modal_action_of_each_observation_and_the_nearest_for_the_unseen(tables):
    obs = tables.observations[[5, 5, 5, 7]]
    pol = sp.bc_policy(obs, np.array([3, 3, 1, 2]), tables)
    assert pol[5] == 3 and pol[7] == 2
    sd = obs.std(0) + 1e-6
    d5 = (((tables.observations[6] - obs[0]) / sd) ** 2).sum()
    d7 = (((tables.observations[6] - obs[3]) / sd) ** 2).sum()
    assert pol[6] == (3 if d5 < d7 else 2)


def test_a_state_policy_decides_each_live_state_once(tables):
    seen = []

    def decide(observation, history):
        seen.append(history.mask.shape)
        return int(observation[-1] > 5)   # SOFA score above 5 -> action 1

    pol = sp.state_policy(decide, tables)
    assert len(seen) == 713 and seen[0] == (1, 0)
    np.testing.assert_array_equal(pol[:713], tables.observations[:713, -1] > 5)


def test_inadmissible_doses_are_counted_per_state_and_per_patient():
    t = icu_sepsis.tables("terminate")
    modal = t.modal()
    assert sp.inadmissible(t, modal) == {"inadmissible_states": 0.0,
                                         "inadmissible_per_patient": 0.0}
    s0 = int(np.argmax(t.mdp.d0))
    bad = modal.copy()
    bad[s0] = int(np.flatnonzero(~t.admissible[s0])[0])
    got = sp.inadmissible(t, bad)
    assert got["inadmissible_states"] == pytest.approx(1 / 713, abs=1e-15)
    # expected visits to s0 by hand: d0 (I - P_pi)^-1 over the live states; each is fatal here
    live = np.flatnonzero(~t.mdp.terminal)
    pi = t.mdp.as_stochastic(bad)
    P_pi = np.einsum("sa,sat->st", pi, t.mdp.P)[np.ix_(live, live)]
    visits = t.mdp.d0[live] @ np.linalg.inv(np.eye(len(live)) - P_pi)
    assert got["inadmissible_per_patient"] == pytest.approx(visits[list(live).index(s0)],
                                                            rel=1e-9)
    assert t.mdp.value(bad) < t.mdp.value(modal)


def test_run_writes_the_table_with_the_references_and_log_policies(tmp_path):
    report = run_sepsis(tmp_path / "out", tmp_path / "store", "tiny",
                        methods=["bc", "tabular", "spibb", "clinicians", "one-step",
                                 "optimal"], sizes=[300])
    by = {r["method"]: r for r in report["summary"]}
    assert by["one-step"]["value"] == pytest.approx(0.8618, abs=1e-4)
    assert by["optimal"]["value"] == pytest.approx(0.8751, abs=1e-4)
    assert by["clinicians"]["value"] == pytest.approx(0.7818, abs=1e-4)
    for m in ("bc", "tabular"):
        assert by[m]["episodes"] == 300 and by[m]["kind"] == "exact"
        assert 0.7 < by[m]["value"] < by["optimal"]["value"]
        assert 0.0 <= by[m]["agree_one_step"] <= 1.0
        assert 0.0 <= by[m]["inadmissible_states"] <= 1.0
    from aoc_cli.baselines.spibb import THRESHOLDS

    assert by["spibb"]["kind"] == "exact" and 0.7 < by["spibb"]["value"] < by["optimal"]["value"]
    assert [r["n_wedge"] for r in report["rows"] if r["method"] == "spibb"][0] in THRESHOLDS
    saved = json.loads((tmp_path / "out" / "summary.json").read_text())
    assert saved["summary"] == report["summary"]
    md = (tmp_path / "out" / "summary.md").read_text()
    assert "| one-step | tables |" in md and "| bc | 300 |" in md
    assert (tmp_path / "out" / "results.csv").read_text().startswith("task,episodes,rows")


def test_bad_bench_arguments_are_refused(tmp_path):
    with pytest.raises(AocError, match="unknown nope"):
        run_sepsis(tmp_path / "o", tmp_path / "s", "tiny", methods=["nope"])
    with pytest.raises(BadSetting, match="sizes: episodes per log") as err:
        run_sepsis(tmp_path / "o", tmp_path / "s", "tiny", methods=["bc"], sizes=[0])
    assert (err.value.param, err.value.value) == ("sizes", [0])
    with pytest.raises(BadSetting, match="seeds must be >= 1") as err:
        run_sepsis(tmp_path / "o", tmp_path / "s", "tiny", seeds=0, methods=["bc"])
    assert message(err.value) == "--seeds must be >= 1, got 0"


def test_cli_bad_method_is_one_line_exit_2(aoc, tmp_path):
    code, _out, err = aoc("bench", "icu-sepsis", "--tiny", "--methods", "aoc,nope",
                          "--out", str(tmp_path / "o"), "--bench-store", str(tmp_path / "s"))
    assert code == 2 and len(err.strip().splitlines()) == 1 and "unknown nope" in err


def test_monte_carlo_of_a_policy_that_reads_a_history_covers_its_exact_value(tmp_path, tables):
    """The modal-action policy rolled out in the package's environment: the 95% interval of
    400 episodes holds its exact value (0.787)."""
    from aoc_cli.control import model_free_session
    from aoc_cli.envs import collect, make_env
    from aoc_cli.store import Store

    data, _ = collect("icu-sepsis", episodes=20, seed=0)
    session = model_free_session(Store(tmp_path).write("log", data))
    modal = tables.modal()
    lookup = {tables.observations[s].astype(np.float32).tobytes(): s for s in range(sp.LIVE)}

    def decide(observation, history):
        return int(modal[lookup[np.asarray(observation, np.float32).tobytes()]])

    result = sp.monte_carlo(decide, session, make_env("icu-sepsis"), 400, seed=5)
    assert result["kind"] == "monte-carlo" and result["episodes"] == 400
    assert result["low"] <= tables.mdp.value(modal) <= result["high"]
    assert result["high"] - result["low"] < 0.1
