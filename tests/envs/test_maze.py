import gymnasium
from gymnasium.utils.env_checker import check_env
import numpy as np
import pytest
from PIL import Image

from aoc_cli.envs import TASKS, collect, make_env
from aoc_cli.envs.maze import EXPERTS, WORLDS, MazeEnv, policy_action
from aoc_cli.errors import AocError


def test_a_move_across_the_wall_is_rejected_and_the_agent_stays():
    env = MazeEnv("maze")
    env.reset(options={"start": (7.5, 3.0)})
    obs, reward, terminated, _tr, info = env.step(np.array([1.0, 0.0], np.float32))
    np.testing.assert_allclose(obs, [7.5, 3.0])
    assert info["rejected"] and reward == pytest.approx(-0.1) and not terminated
    # From the other side too, and diagonally through a closed stretch.
    world = WORLDS["maze"]
    # right to left; diagonal; diagonal ending in the top gap's height but crossing at
    # y = 14.2 + 0.5 / 6 < 14.5 (below the gap); a move ending exactly on the wall.
    pos = np.array([[8.4, 12.0], [7.2, 10.0], [7.9, 14.2], [7.5, 5.0]])
    act = np.array([[-1.0, 0.0], [1.0, 1.0], [0.6, 0.5], [0.5, 0.0]])
    new, rejected = world.move(pos, act)
    assert rejected.tolist() == [True, True, True, True]
    np.testing.assert_array_equal(new, pos)


def test_moves_through_the_gaps_are_allowed():
    world = WORLDS["maze"]
    pos = np.array([[7.5, 8.0], [8.5, 15.5], [7.6, 7.4], [8.0, 8.0]])
    act = np.array([[1.0, 0.0], [-1.0, 0.3], [0.8, 0.4], [0.5, -0.5]])
    new, rejected = world.move(pos, act)
    assert not rejected.any()
    np.testing.assert_allclose(new, np.clip(pos + act, 0, 16))
    # Gap bounds of the two-gates world.
    new, rejected = WORLDS["two-gates"].move(np.array([[7.5, 3.5], [7.5, 8.0]]),
                                             np.array([[1.0, 0.0], [1.0, 0.0]]))
    assert rejected.tolist() == [False, True]


def test_positions_are_clipped_to_the_square():
    new, rejected = WORLDS["maze"].move(np.array([[0.2, 15.8]]), np.array([[-1.0, 1.0]]))
    np.testing.assert_allclose(new, [[0.0, 16.0]])
    assert not rejected.any()


def test_each_expert_reaches_its_own_goal_in_95_percent_of_episodes():
    data, summary = collect("maze", episodes=200, seed=0)
    rates = {r["policy"]: r["own_goal_rate"] for r in summary}
    assert set(rates) == {"pi1", "pi2", "pi3", "pi4"} and min(rates.values()) >= 0.95
    codes, labels = data.tags["policy"]
    starts = data.episode_starts
    for e in range(data.n_episodes):
        name = labels[codes[starts[e]]]
        start, goal = EXPERTS[name]
        np.testing.assert_allclose(data.observations[starts[e]], start)
    # The data carries the test task's reward: +10 exactly where pi3 / pi4 reach (16, 0).
    big = data.rewards > 5
    assert set(np.array(labels)[codes[big]]) == {"pi3", "pi4"}
    assert np.all(data.terminals[big])
    assert {r["policy"]: r["success_rate"] for r in summary} == {
        "pi1": 0.0, "pi2": 0.0, "pi3": 1.0, "pi4": 1.0}


@pytest.mark.parametrize("expert", ["pi1", "pi2", "pi3", "pi4"])
def test_no_single_expert_reaches_the_test_goal_from_the_start(expert):
    env = make_env("maze")
    rng = np.random.default_rng(1)
    for seed in range(10):
        obs, info = env.reset(seed=seed)
        np.testing.assert_array_equal(obs, [0.0, 0.0])
        done, steps = False, 0
        while not done:
            action = policy_action(expert, obs[None].astype(np.float64), rng)[0]
            obs, _r, term, trunc, info = env.step(action.astype(np.float32))
            done, steps = term or trunc, steps + 1
        assert steps == 100 and not info["success"]
        assert TASKS["maze"].success(info) is False


def test_chaining_two_experts_solves_the_test_task():
    env = make_env("maze")
    rng = np.random.default_rng(2)
    for first, second, via in (("pi1", "pi3", (8.0, 16.0)), ("pi2", "pi4", (8.0, 8.0))):
        obs, _ = env.reset(seed=0)
        total, done, policy = 0.0, False, first
        while not done:
            if np.linalg.norm(obs - np.array(via)) <= 0.5:
                policy = second
            a = policy_action(policy, obs[None].astype(np.float64), rng)[0].astype(np.float32)
            obs, r, term, trunc, info = env.step(a)
            total, done = total + r, term or trunc
        assert info["success"] and term and total > 4.0


def test_two_gates_policies_pass_their_own_gate_and_reach_the_goal():
    data, summary = collect("two-gates", episodes=100, seed=0)
    assert all(r["success_rate"] >= 0.95 for r in summary)
    codes, labels = data.tags["policy"]
    for e in range(data.n_episodes):
        rows = slice(data.episode_starts[e], data.episode_starts[e + 1])
        path = data.observations[rows]
        assert len(path) <= 32
        left = path[:, 0] < 8.0
        cross = int(np.argmin(left)) if not left.all() else None
        assert cross is not None and cross > 0
        y = path[cross - 1:cross + 1, 1].mean()
        gate = labels[codes[data.episode_starts[e]]]
        assert (y < 8.0) == (gate == "lower-gate")


def test_evaluation_envs_have_the_tasks_start_goal_and_horizon():
    env = gymnasium.make("aoc/TwoGates-v0")
    obs, info = env.reset(seed=0)
    np.testing.assert_array_equal(obs, [0.0, 8.0])
    assert info["success"] is False
    steps, done = 0, False
    while not done:
        obs, r, term, trunc, info = env.step(np.zeros(2, np.float32))
        steps, done = steps + 1, term or trunc
    assert steps == 32 and trunc and not term and r == pytest.approx(-0.1)
    env = MazeEnv("two-gates")
    env.reset(options={"start": (15.5, 8.0)})
    _o, r, term, _tr, info = env.step(np.array([0.4, 0.0], np.float32))
    assert term and info["success"] and r == pytest.approx(9.9)
    check_env(MazeEnv("maze"), skip_render_check=True)


@pytest.mark.parametrize("task", ["maze", "two-gates"])
def test_plot_trajectories_draws_a_png(tmp_path, task):
    data, _ = collect(task, episodes=8, seed=0)
    t = TASKS[task]
    starts = data.episode_starts
    paths = [t.trajectory(data.observations[starts[e]:starts[e + 1]]) for e in range(8)]
    codes, labels = data.tags["policy"]
    out = tmp_path / f"{task}.png"
    t.plot_trajectories(paths, out, title=task, labels=[labels[codes[s]] for s in starts[:-1]])
    img = np.asarray(Image.open(out).convert("RGB"))
    assert img.shape[0] >= 400 and img.shape[1] >= 400
    assert len(np.unique(img.reshape(-1, 3), axis=0)) > 20  # more than a blank canvas
    with pytest.raises(AocError, match=r"\(T, 2\)"):
        t.plot_trajectories([np.zeros((5, 3))], tmp_path / "bad.png")
