import gymnasium
import numpy as np
import pytest

from aoc_cli.envs import TASKS, collect, make_env
from aoc_cli.errors import AocError
from aoc_cli.store import Store

SMALL = {"pendulum-het": {"steps": 900}, "pendulum-het-upright": {"steps": 700},
         "maze": {"episodes": 12}, "two-gates": {"episodes": 6}, "lunar": {"steps": 600},
         "ward": {"episodes": 30}, "icu-sepsis": {"episodes": 40},
         "icu-sepsis-terminate": {"episodes": 40}, "icu-cohort": {"episodes": 40}}


def test_the_tasks_with_their_evaluation_settings():
    assert list(TASKS) == ["pendulum-het", "pendulum-het-upright", "maze", "two-gates", "lunar",
                          "ward", "icu-sepsis", "icu-sepsis-terminate", "icu-cohort"]
    assert TASKS["maze"].start == (0.0, 0.0) and TASKS["maze"].goal == (16.0, 0.0)
    assert TASKS["maze"].horizon == 100 and TASKS["maze"].default_episodes == 1000
    assert TASKS["two-gates"].start == (0.0, 8.0) and TASKS["two-gates"].goal == (16.0, 8.0)
    assert TASKS["two-gates"].horizon == 32
    assert TASKS["pendulum-het"].horizon == 200 and TASKS["lunar"].gym_id == \
        "LunarLanderContinuous-v3"
    assert TASKS["pendulum-het"].success({"system": "normal"}) is None
    assert TASKS["maze"].success([{"success": False}, {"success": True}]) is True


@pytest.mark.parametrize("name", list(TASKS))
def test_make_env_gives_the_evaluation_env_with_its_time_limit(name):
    env = make_env(name)
    assert env.spec.max_episode_steps == TASKS[name].horizon
    obs, _ = env.reset(seed=0)
    assert env.observation_space.contains(obs)
    if name.startswith("pendulum"):
        assert env.unwrapped.system == "normal"


def test_gym_ids_are_registered_and_any_gymnasium_id_works():
    for gid in ("aoc/PendulumHet-v0", "aoc/PendulumHetUpright-v0", "aoc/Maze-v0",
                "aoc/TwoGates-v0"):
        assert gid in gymnasium.registry
    env = gymnasium.make("aoc/PendulumHet-v0", system="converse")
    assert env.unwrapped.system == "converse"
    assert make_env("Pendulum-v1").spec.id == "Pendulum-v1"
    assert make_env("aoc_cli.envs:aoc/TwoGates-v0").spec.max_episode_steps == 32
    with pytest.raises(AocError, match="pendulum-het, pendulum-het-upright, maze"):
        make_env("NoSuchEnv-v9")


@pytest.mark.parametrize("name", list(TASKS))
def test_same_seed_same_arrays_other_seed_other_arrays(name):
    a, sa = collect(name, seed=7, **SMALL[name])
    b, sb = collect(name, seed=7, **SMALL[name])
    c, _ = collect(name, seed=8, **SMALL[name])
    for key in ("observations", "actions", "rewards", "terminals", "truncations",
                "episode_starts"):
        x, y = getattr(a, key), getattr(b, key)
        if x is None:  # ward is reward-free
            assert y is None and name == "ward"
            continue
        assert x.dtype == y.dtype and x.tobytes() == y.tobytes(), key
    for tag in a.tags:
        np.testing.assert_array_equal(a.tags[tag][0], b.tags[tag][0])
    assert sa == sb
    assert not np.array_equal(a.observations[: len(c.observations)],
                              c.observations[: len(a.observations)])


def test_same_seed_gives_identical_corpus_files(tmp_path):
    store = Store(tmp_path)
    hashes = []
    for name in ("one", "two"):
        data, _ = collect("maze", episodes=8, seed=3)
        hashes.append(store.write(name, data).hash)
    assert hashes[0] == hashes[1]
    assert (tmp_path / "one" / "corpus.h5").read_bytes() == \
        (tmp_path / "two" / "corpus.h5").read_bytes()


@pytest.mark.parametrize("name", ["pendulum-het", "maze", "two-gates", "icu-sepsis",
                                  "icu-cohort"])
def test_steps_gives_exactly_that_many_rows(name):
    data, summary = collect(name, steps=333, seed=0)
    assert data.n_rows == 333 and sum(r["rows"] for r in summary) == 333
    assert data.terminals.sum() + data.truncations.sum() == data.n_episodes
    assert np.all(data.terminals[data.episode_starts[1:] - 1]
                  | data.truncations[data.episode_starts[1:] - 1])


def test_bad_budgets_and_unknown_tasks_are_refused():
    with pytest.raises(AocError, match="positive"):
        collect("maze", steps=0)
    with pytest.raises(AocError, match="positive"):
        collect("lunar", episodes=-2)
    with pytest.raises(AocError, match="not both"):
        collect("maze", steps=10, episodes=2)
    with pytest.raises(AocError, match="unknown task 'mazes'"):
        collect("mazes")
