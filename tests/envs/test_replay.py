"""``--behaviour replay``: an agent that starts random and improves, tagged, the same per seed."""

import numpy as np
import pytest

from aoc_cli.envs import collect, replay
from aoc_cli.errors import AocError


def test_the_schedule_starts_random_then_lowers_the_noise_from_one_to_zero():
    assert replay.noise_at(0.0) is None and replay.noise_at(0.099) is None
    assert replay.noise_at(0.1) == pytest.approx(1.0)
    assert replay.noise_at(0.55) == pytest.approx(0.5)
    assert replay.noise_at(1.0) == pytest.approx(0.0)
    assert replay.label(None) == "random" and replay.label(0.46) == "replay-noise0.5"


def _per_episode(data, name):
    starts = data.episode_starts[:-1]
    codes, labels = data.tags[name]
    return [labels[c] for c in codes[starts]]


def test_pendulum_replay_is_tagged_ordered_and_the_same_per_seed():
    data, summary = collect("pendulum-het", steps=8_000, seed=3, behaviour="replay")
    again, _ = collect("pendulum-het", steps=8_000, seed=3, behaviour="replay")
    np.testing.assert_array_equal(data.actions, again.actions)
    np.testing.assert_array_equal(data.observations, again.observations)
    assert data.source["behaviour"] == "replay"
    systems, policies = _per_episode(data, "system"), _per_episode(data, "policy")
    noise = data.columns["noise_std"][data.episode_starts[:-1]]
    for system in ("normal", "converse"):
        mine = [i for i, s in enumerate(systems) if s == system]     # 20 episodes each
        assert [policies[i] for i in mine[:2]] == ["random", "random"]   # the first 10%
        assert np.isnan(noise[mine[:2]]).all()
        rest = noise[mine[2:]]
        assert rest[0] == pytest.approx(1.0) and np.all(np.diff(rest) < 0) and rest[-1] < 0.1
        assert all(p.startswith("replay-noise") for p in (policies[i] for i in mine[2:]))
    # the random episodes' torques are uniform, the rest follow the controller: better returns
    normal = {r["policy"]: r["mean_return"] for r in summary if r["system"] == "normal"}
    assert max(v for p, v in normal.items() if p != "random") > normal["random"] + 500
    other, _ = collect("pendulum-het", steps=8_000, seed=4, behaviour="replay")
    assert not np.array_equal(other.actions, data.actions)


def test_lunar_replay_and_tasks_without_it():
    data, _ = collect("lunar", steps=3_000, seed=0, behaviour="replay")
    policies = _per_episode(data, "policy")
    assert policies[0] == "random" and policies[-1].startswith("replay-noise")
    assert data.n_rows == 3_000 and len(data.columns["noise_std"]) == 3_000
    with pytest.raises(AocError, match="no behaviour 'replay'"):
        collect("maze", episodes=2, behaviour="replay")
    with pytest.raises(AocError, match="no behaviour 'bogus'"):
        collect("lunar", steps=100, behaviour="bogus")
