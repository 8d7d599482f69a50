import gymnasium
import numpy as np
import pytest
from gymnasium.envs.classic_control.pendulum import PendulumEnv

from aoc_cli.envs import TASKS, collect, make_env
from aoc_cli.envs.pendulum_het import (
    PendulumHetEnv,
    observe,
    pendulum_step,
    rollout_batch,
    swingup_action,
)


#: numpy's vectorised sin/cos/pow may differ from the scalar C library in the last bit, and
#: which one a machine uses depends on its CPU (AVX-512 or not): compare two code paths to a
#: few ulp of the quantities that enter the sum, never bit for bit.
ULPS = 8


def assert_close_to_ulps(got, want, scale, dtype=np.float64):
    """|got - want| <= ULPS ulp of ``scale`` (the magnitude of the terms summed)."""
    tol = ULPS * np.finfo(dtype).eps * scale
    np.testing.assert_allclose(np.asarray(got, np.float64), np.asarray(want, np.float64),
                               rtol=0, atol=tol)


def test_vectorised_step_equals_gymnasiums_pendulum_to_a_few_ulp():
    rng = np.random.default_rng(0)
    b = 500
    theta = rng.uniform(-3 * np.pi, 3 * np.pi, b)
    theta_dot = rng.uniform(-8, 8, b)
    env = PendulumEnv()
    env.reset(seed=0)
    for _ in range(5):
        torque = rng.uniform(-3, 3, b).astype(np.float32)  # also beyond the torque limit
        new_theta, new_theta_dot, reward = pendulum_step(theta, theta_dot, torque)
        for i in range(b):
            env.state = np.array([theta[i], theta_dot[i]])
            obs, r, *_ = env.step(torque[i:i + 1])
            # reward: float64 terms up to pi^2 + 0.1 * 8^2, and 0.001 u^2 <= 0.004 computed in
            # float32 as gymnasium does (a float32 pow: a few float32 ulp of that term)
            assert_close_to_ulps(r, reward[i], scale=20.0 + 0.004 * np.finfo(np.float32).eps
                                 / np.finfo(np.float64).eps)
            # state: angles up to 3 pi plus a velocity step, velocities up to 8 + 15 * 0.05
            assert_close_to_ulps(env.state, [new_theta[i], new_theta_dot[i]], scale=16.0)
            expected = observe(new_theta[i:i + 1], new_theta_dot[i:i + 1])[0]
            assert_close_to_ulps(obs, expected, scale=8.0, dtype=np.float32)
        theta, theta_dot = new_theta, new_theta_dot


def test_converse_system_applies_the_negated_torque():
    state = np.array([0.3, 0.5])
    u = np.array([1.5], dtype=np.float32)
    after = {}
    for system in ("normal", "converse"):
        env = PendulumHetEnv(system=system)
        env.reset(seed=0)
        env.state = state.copy()
        obs, reward, _t, _tr, info = env.step(u)
        assert info["system"] == system
        after[system] = (obs, reward)
    # Same state, same commanded action: the torque's push on the velocity has opposite signs.
    push = 3.0 * 1.5 * 0.05
    free = 0.5 + 15 * np.sin(0.3) * 0.05
    assert after["normal"][0][2] == pytest.approx(free + push, abs=1e-5)
    assert after["converse"][0][2] == pytest.approx(free - push, abs=1e-5)
    # ... and the converse system is exactly gymnasium's pendulum driven by -u.
    ref = PendulumEnv()
    ref.reset(seed=0)
    ref.state = state.copy()
    ref_obs, ref_reward, *_ = ref.step(-u)
    assert_close_to_ulps(after["converse"][0], ref_obs, scale=8.0, dtype=np.float32)
    assert_close_to_ulps(after["converse"][1], ref_reward, scale=20.0)


def test_stored_action_is_the_commanded_one_and_explains_the_next_state():
    data, _ = collect("pendulum-het", steps=2000, seed=5)
    obs, act = data.observations.astype(np.float64), data.actions[:, 0].astype(np.float64)
    codes, labels = data.tags["system"]
    sign = np.where(np.array(labels)[codes] == "converse", -1.0, 1.0)
    ends = data.episode_starts[1:] - 1
    rows = np.setdiff1d(np.arange(data.n_rows), ends)
    theta = np.arctan2(obs[rows, 1], obs[rows, 0])
    predicted = np.clip(obs[rows, 2] + (15 * np.sin(theta) + 3 * sign[rows] * act[rows]) * 0.05,
                        -8, 8)
    np.testing.assert_allclose(predicted, obs[rows + 1, 2], atol=1e-4)
    # Reading the stored action as the applied one would be wrong in the converse rows.
    conv = rows[sign[rows] < 0]
    th_c = np.arctan2(obs[conv, 1], obs[conv, 0])
    wrong = np.clip(obs[conv, 2] + (15 * np.sin(th_c) + 3 * act[conv]) * 0.05, -8, 8)
    assert np.mean(np.abs(wrong - obs[conv + 1, 2]) > 1e-3) > 0.5
    assert np.all(np.abs(data.actions) <= 2.0)


def test_half_the_rows_come_from_each_system_with_every_policy():
    data, summary = collect("pendulum-het", steps=4100, seed=1)
    codes, labels = data.tags["system"]
    counts = {lab: int(np.sum(codes == i)) for i, lab in enumerate(labels)}
    assert counts == {"normal": 2050, "converse": 2050}
    assert {(r["system"], r["policy"]) for r in summary} == {
        (s, p) for s in ("normal", "converse") for p in TASKS["pendulum-het"].policies}
    assert data.truncations.sum() == data.n_episodes and not data.terminals.any()


def _returns(policy_system, dynamics, n=48, seed=0, random=False):
    rng = np.random.default_rng(seed)
    theta, theta_dot = rng.uniform(-np.pi, np.pi, n), rng.uniform(-1, 1, n)
    total = np.zeros(n)
    sign = 1.0 if dynamics == "normal" else -1.0
    for _ in range(200):
        obs = observe(theta, theta_dot)
        u = rng.uniform(-2, 2, n) if random else swingup_action(obs, policy_system)
        theta, theta_dot, r = pendulum_step(theta, theta_dot, (sign * u).astype(np.float32))
        total += r
    return total.mean()


@pytest.mark.parametrize("system", ["normal", "converse"])
def test_behaviour_policy_is_good_in_its_own_system_and_bad_in_the_other(system):
    other = "converse" if system == "normal" else "normal"
    own = _returns(system, system)
    wrong = _returns(system, other)
    random = _returns(system, system, random=True)
    assert own > -250, own          # good control from random starts is near -150
    assert random < -900, random
    assert wrong < -900, wrong      # the heterogeneity is real
    assert own - random > 600


def test_controller_swings_up_and_balances_in_the_gymnasium_env():
    for system in ("normal", "converse"):
        env = make_env("pendulum-het", system=system)
        returns = []
        for seed in range(3):
            obs, _ = env.reset(seed=seed)
            total, done = 0.0, False
            while not done:
                u = swingup_action(obs[None], system).astype(np.float32)
                obs, r, term, trunc, info = env.step(u)
                total += r
                done = term or trunc
            returns.append(total)
            assert info["system"] == system and abs(np.arctan2(obs[1], obs[0])) < 0.1
        assert np.mean(returns) > -350


def test_upright_variant_starts_exactly_upright_at_rest():
    env = gymnasium.make("aoc/PendulumHetUpright-v0")
    for seed in range(3):
        obs, info = env.reset(seed=seed)
        np.testing.assert_array_equal(obs, np.array([1.0, 0.0, 0.0], np.float32))
    assert info["system"] == "normal"
    obs, _ = make_env("pendulum-het").reset(seed=1)
    assert not np.array_equal(obs, [1.0, 0.0, 0.0])


def test_rollout_batch_noise_levels_order_the_returns():
    rng = np.random.default_rng(3)
    pols = ["swingup-noise0"] * 40 + ["swingup-noise2"] * 40 + ["random"] * 40
    eps = rollout_batch(pols, ["normal"] * 120, np.full(120, 200), False, rng)
    ret = np.array([ep.rewards.sum() for ep in eps]).reshape(3, 40).mean(axis=1)
    assert ret[0] > ret[1] > ret[2]
