"""`aoc evaluate --workers`: the chunks scored as Ray tasks give the steps and the metrics of
the run in one process."""

import dataclasses

import numpy as np
import pytest
import ray

from aoc_cli.belief import BeliefConfig, train_model
from aoc_cli.control import ControllerConfig, open_session
from aoc_cli.index import build_index
from aoc_cli.envs import collect
from aoc_cli.evaluation.ray import evaluate_on_ray
from aoc_cli.evaluation.score import score_log
from aoc_cli.store import Store


@pytest.fixture(scope="module")
def ward(tmp_path_factory):
    root = tmp_path_factory.mktemp("ward-ray")
    store = Store(root)
    store.write("ward", collect("ward", episodes=60, seed=0)[0])
    store.write("held", collect("ward", episodes=12, seed=1)[0])
    corpus = store.corpus("ward")
    small = dict(history_length=1, hidden=32, belief_dim=4, max_epochs=3, threads=1, seed=0)
    train_model(corpus, BeliefConfig(mode="value", value="outcome", **small), "value")
    build_index(corpus, "value")
    yield root, store
    ray.shutdown()


def _equal(a, b):
    for f in dataclasses.fields(a):
        x, y = getattr(a, f.name), getattr(b, f.name)
        if f.name == "baselines":
            assert x.keys() == y.keys()
            for k in x:
                for kk in x[k]:
                    np.testing.assert_array_equal(x[k][kk], y[k][kk])
        elif x is None:
            assert y is None
        else:
            np.testing.assert_array_equal(x, y)


@pytest.mark.parametrize("data", ["held", "ward"])  # a held-out corpus; NAME itself
def test_chunks_on_two_workers_give_the_single_process_result(ward, data):
    root, store = ward
    corpus = store.corpus("ward")
    config = ControllerConfig()
    session = open_session(corpus, "value", config=config, seed=3)
    held = store.corpus(data)
    one, res_one = score_log(session, held, ["knn", "bc"], seed=3, chunk_steps=300)
    two, res_two = evaluate_on_ray(root, "ward", data, "value", "default", config,
                                   ["knn", "bc"], seed=3, workers=2, chunk_steps=300)
    assert len(res_two.row) == held.n_rows
    _equal(res_one, res_two)
    drop = ("seconds", "steps_per_second", "ope_seconds")
    assert {k: v for k, v in one.items() if k not in drop} == \
        {k: v for k, v in two.items() if k not in drop}


def test_cli_workers_print_the_same_summary(ward):
    import json
    import os

    from tests.conftest import run_aoc

    root, _store = ward
    env = {**os.environ, "AOC_STORE": str(root)}
    env.pop("RAY_ADDRESS", None)
    args = ("evaluate", "ward", "--data", "held", "--model", "value", "--format", "json")
    code, one, err = run_aoc(*args, env=env)
    assert code == 0, err
    code, two, err = run_aoc(*args, "--workers", "2", env=env)
    assert code == 0, err
    drop = ("seconds", "steps_per_second", "ope_seconds")
    one, two = json.loads(one), json.loads(two)
    assert {k: v for k, v in one.items() if k not in drop} == \
        {k: v for k, v in two.items() if k not in drop}
    code, _out, err = run_aoc(*args, "--workers", "0", env=env)
    assert code == 2 and "--workers must be >= 1" in err
