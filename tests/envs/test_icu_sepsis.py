"""icu-sepsis: the package's tables, their exact values, the log and the environment."""

import subprocess
import sys

import numpy as np
import pytest

from aoc_cli.envs import collect, make_env
from aoc_cli.envs import icu_sepsis as sepsis
from aoc_cli.envs.tabular import greedy


@pytest.fixture(scope="module")
def tables():
    return sepsis.tables("mean")


def test_exact_values_of_the_reference_policies(tables):
    """The values the issue measured from the package's tables (3 decimals)."""
    mdp = tables.mdp
    q_clinicians = mdp.q_values(tables.clinicians)
    one_step = greedy(q_clinicians, tables.clinicians > 0)
    v_star, _ = mdp.optimal()
    values = {"random": mdp.value(tables.behaviour("random")),
              "clinicians": mdp.value(tables.clinicians), "modal": mdp.value(tables.modal()),
              "one-step": mdp.value(one_step), "optimal": float(mdp.d0 @ v_star)}
    expected = {"random": 0.780, "clinicians": 0.782, "modal": 0.787, "one-step": 0.862,
                "optimal": 0.875}
    for name, value in expected.items():
        assert values[name] == pytest.approx(value, abs=5e-4), name
    # Q of the clinicians averaged under their own policy is their value
    v_clin = mdp.state_values(tables.clinicians)
    np.testing.assert_allclose((tables.clinicians * q_clinicians).sum(1), v_clin, atol=1e-12)


def test_terminate_variant_kills_on_inadmissible_actions(tables):
    term = sepsis.tables("terminate")
    s, a = np.argwhere(~term.admissible[:713])[0]
    assert term.mdp.P[s, a, sepsis.STATE_DEATH] == 1.0 and term.mdp.r[s, a] == 0.0
    assert np.array_equal(term.mdp.P[term.admissible], tables.mdp.P[tables.admissible])
    # the modal action is always admissible: same value in both variants; the clinicians'
    # own policy tries inadmissible actions and loses patients
    assert term.admissible[np.arange(713), tables.modal()[:713]].all()
    assert term.mdp.value(tables.modal()) == pytest.approx(tables.mdp.value(tables.modal()),
                                                           abs=1e-12)
    assert term.mdp.value(term.clinicians) < tables.mdp.value(tables.clinicians) - 0.3


def test_the_log_holds_states_propensities_labels_and_patient_ids(tables):
    data, summary = collect("icu-sepsis", episodes=3000, seed=1)
    state = data.columns["state"].astype(np.int64)
    assert np.array_equal(data.columns["state"], state) and state.max() < 713
    np.testing.assert_array_equal(data.observations, tables.observations[state].astype(np.float32))
    np.testing.assert_array_equal(data.columns["propensity"],
                                  tables.clinicians[state, data.actions])
    assert data.columns["propensity"].min() > 0
    assert data.observation_space["names"][:3] == ["gender", "mechvent", "max_dose_vaso"]
    assert data.observation_space["names"][-1] == "sofa_score" and data.observations.shape[1] == 48
    assert data.action_space["names"][2 * 5 + 0] == "fluids=2,vaso=0"
    assert len(set(data.episode_ids)) == data.n_episodes == 3000
    # one reward, at a terminal step into survival; no step after a terminal one
    last = data.episode_starts[1:] - 1
    assert np.all(data.rewards[np.setdiff1d(np.arange(data.n_rows), last)] == 0)
    assert data.terminals[last].all()
    # survival in the log is the exact value of the clinicians, within 4 standard errors
    mean, exact = summary[0]["mean_return"], summary[0]["exact_value"]
    assert exact == pytest.approx(0.7818, abs=1e-4)
    assert abs(mean - exact) < 4 * np.sqrt(exact * (1 - exact) / 3000)


def test_the_state_to_state_steps_follow_the_tables(tables):
    """In a log of the uniform policy every logged step has positive probability in the
    tables, and the count of each next state is its expected count (the rows' transition
    probabilities, given that the patient stayed under treatment) within 6 standard errors."""
    data, _ = collect("icu-sepsis", episodes=4000, seed=2, policy="random")
    assert data.tags["policy"][1][data.tags["policy"][0][0]] == "random"
    np.testing.assert_allclose(data.columns["propensity"], 1 / 25)
    state = data.columns["state"].astype(np.int64)
    cont = np.ones(data.n_rows - 1, dtype=bool)
    cont[data.episode_starts[1:-1] - 1] = False        # the step continues its episode
    s, a, s2 = state[:-1][cont], data.actions[:-1][cont], state[1:][cont]
    assert tables.mdp.P[s, a, s2].min() > 0
    p_live = tables.mdp.P[s, a, :713]
    expected = (p_live / p_live.sum(axis=1, keepdims=True)).sum(axis=0)
    observed = np.bincount(s2, minlength=713)
    assert np.all(np.abs(observed - expected) <= 6 * np.sqrt(expected) + 1)


def test_the_environment_observes_the_features_of_its_state(tables):
    env = make_env("icu-sepsis")
    obs, info = env.reset(seed=3)
    assert obs.shape == (48,) and obs.dtype == np.float32
    np.testing.assert_array_equal(obs, tables.observations[info["state"]].astype(np.float32))
    assert env.action_space.n == 25
    done = False
    while not done:
        obs, reward, terminated, truncated, info = env.step(int(tables.modal()[info["state"]]))
        done = terminated or truncated
    assert info["state"] in (713, 714, 715) and reward == float(info["state"] == 714)
    term = make_env("icu-sepsis-terminate")
    seed, (_, info) = 0, term.reset(seed=0)
    while tables.admissible[info["state"]].all():
        seed += 1
        _, info = term.reset(seed=seed)
    bad = int(np.flatnonzero(~tables.admissible[info["state"]])[0])
    _, reward, terminated, _, info = term.step(bad)
    assert terminated and info["state"] == sepsis.STATE_DEATH and reward == 0.0


def test_importing_the_package_prints_nothing():
    code = ("from aoc_cli.envs import icu_sepsis as s; s.package(); s.make_sepsis_env(); "
            "import aoc_cli.envs; aoc_cli.envs.make_env('icu-sepsis').reset(seed=0)")
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout == "" and proc.stderr == ""
