"""A Minari export is data d3rlpy trains on: an ``MDPDataset`` built from the episodes that
``minari.load_dataset`` reads (no environment), then a few gradient steps (the bench extra)."""

import numpy as np
import pytest

from aoc_cli.envs import collect
from aoc_cli.formats import export
from aoc_cli.store import Store

d3rlpy = pytest.importorskip("d3rlpy", reason="d3rlpy comes with the bench extra")


def mdp_dataset(ds):
    """d3rlpy MDPDataset from a Minari dataset's episodes: the T observations at which the
    T actions were taken (the T + 1-th, after the last action, is not a step)."""
    obs, act, rew, term, trunc = [], [], [], [], []
    for ep in ds.iterate_episodes():
        obs.append(ep.observations[:-1])
        act.append(ep.actions)
        rew.append(ep.rewards)
        term.append(ep.terminations)
        t = ep.truncations.copy()
        t[-1] |= not ep.terminations[-1]  # d3rlpy needs every episode to end
        trunc.append(t)
    return d3rlpy.dataset.MDPDataset(
        np.concatenate(obs), np.concatenate(act), np.concatenate(rew),
        np.concatenate(term), np.concatenate(trunc),
        action_space=(d3rlpy.constants.ActionSpace.DISCRETE if act[0].ndim == 1
                      else d3rlpy.constants.ActionSpace.CONTINUOUS))


@pytest.mark.parametrize("task", ["maze", "ward"])
def test_minari_export_trains_a_d3rlpy_model_without_an_environment(task, tmp_path,
                                                                    monkeypatch):
    import minari

    monkeypatch.setenv("MINARI_DATASETS_PATH", str(tmp_path / "minari"))
    store = Store(tmp_path / "store")
    data, _ = collect(task, steps=400, seed=0)
    store.write(task, data)
    export(task, "minari", tmp_path / "minari" / f"{task}-v0", store=store)
    ds = minari.load_dataset(f"{task}-v0")
    dataset = mdp_dataset(ds)
    c = store.corpus(task)
    # d3rlpy counts T transitions in an episode that terminated, T - 1 in one cut off
    ended = c.read("terminals")[c.episode_starts[1:] - 1]
    assert dataset.size() == c.n_episodes
    assert dataset.transition_count == c.n_rows - int((~ended).sum())
    np.testing.assert_array_equal(dataset.episodes[0].observations,
                                  c.observations[:c.episode_starts[1]])
    algo = (d3rlpy.algos.DiscreteBCConfig() if c.discrete else d3rlpy.algos.BCConfig()
            ).create(device="cpu:0")
    algo.build_with_dataset(dataset)
    before = algo.predict(c.observations[:8].astype(np.float32))
    log = algo.fit(dataset, n_steps=20, n_steps_per_epoch=20, show_progress=False,
                   save_interval=10**9, experiment_name=None,
                   logger_adapter=d3rlpy.logging.NoopAdapterFactory())
    (_epoch, metrics), = log
    assert np.isfinite(metrics["loss"])
    after = algo.predict(c.observations[:8].astype(np.float32))
    assert after.shape == before.shape == ((8,) if c.discrete else (8, c.action_dim))
