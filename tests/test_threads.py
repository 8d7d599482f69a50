"""The thread context (aoc_cli.threads): the library sets thread pools for its own work only and
gives the caller's settings back; OMP_WAIT_POLICY is the command's choice, not an import's."""

import os
import subprocess
import sys

import faiss
import numpy as np
import pytest
import torch

from aoc_cli.belief import BeliefConfig, train_model
from aoc_cli.control import ControllerConfig, HistoryBuffer
from aoc_cli.envs import collect
from aoc_cli.index import build_index
from aoc_cli.control import open_session
from aoc_cli.store import Store
from aoc_cli.threads import one_thread, thread_limits


@pytest.fixture
def two_threads():
    """The caller's setting: two threads in torch and FAISS (restored after the test)."""
    before = torch.get_num_threads(), faiss.omp_get_max_threads()
    torch.set_num_threads(2)
    faiss.omp_set_num_threads(2)
    yield
    torch.set_num_threads(before[0])
    faiss.omp_set_num_threads(before[1])


def test_thread_limits_set_the_pools_for_the_block_and_give_them_back(two_threads):
    with one_thread():
        assert (torch.get_num_threads(), faiss.omp_get_max_threads()) == (1, 1)
        with thread_limits(torch=3):  # nested: only the pool named changes
            assert (torch.get_num_threads(), faiss.omp_get_max_threads()) == (3, 1)
        assert torch.get_num_threads() == 1
    assert (torch.get_num_threads(), faiss.omp_get_max_threads()) == (2, 2)
    with pytest.raises(RuntimeError):
        with one_thread():
            raise RuntimeError("an error inside the block")
    assert (torch.get_num_threads(), faiss.omp_get_max_threads()) == (2, 2)


@pytest.fixture(scope="module")
def maze(tmp_path_factory):
    store = Store(tmp_path_factory.mktemp("threads"))
    corpus = store.write("maze", collect("maze", episodes=40, seed=0)[0])
    train_model(corpus, BeliefConfig(seed=0, threads=1, max_epochs=2), "default")
    build_index(corpus)
    return corpus


def test_a_control_step_runs_on_one_thread_and_leaves_the_callers_setting(maze, two_threads):
    session = open_session(maze, config=ControllerConfig(epsilon=0.1), seed=0)
    assert torch.get_num_threads() == 2  # opening a session changes nothing
    seen = []
    beliefs = session.model.beliefs

    def recording(*args, **kw):
        seen.append((torch.get_num_threads(), faiss.omp_get_max_threads()))
        return beliefs(*args, **kw)

    session.controller.model.beliefs = recording
    buf = HistoryBuffer(session.model.history_length, 2, 2, discrete=False)
    decision = session.controller.decide(np.zeros(2, np.float32), buf.history())
    assert np.isfinite(decision.value) and seen == [(1, 1)]
    assert (torch.get_num_threads(), faiss.omp_get_max_threads()) == (2, 2)


def test_training_sets_its_threads_for_its_own_duration(maze, two_threads):
    seen = []
    train_model(maze, BeliefConfig(seed=0, threads=1, max_epochs=1), "one",
                progress=lambda *report: seen.append(torch.get_num_threads()))
    assert seen and set(seen) == {1}
    assert torch.get_num_threads() == 2


def _wait_policy(code: str, **env) -> str:
    base = {k: v for k, v in os.environ.items() if k != "OMP_WAIT_POLICY"}
    out = subprocess.run([sys.executable, "-c", code + "; import os; "
                          "print(os.environ.get('OMP_WAIT_POLICY'))"],
                         env={**base, **env}, capture_output=True, text=True, check=True)
    return out.stdout.strip()


def test_importing_the_library_leaves_omp_wait_policy_alone_the_command_sets_it():
    assert _wait_policy("import aoc_cli, aoc_cli.index.build, aoc_cli.control") == "None"
    assert _wait_policy("import aoc_cli.cli.app") == "PASSIVE"
    assert _wait_policy("import aoc_cli.cli.app", OMP_WAIT_POLICY="ACTIVE") == "ACTIVE"


def test_a_rollout_runs_every_policys_steps_on_one_thread(maze, two_threads):
    from aoc_cli.baselines import make_baseline
    from aoc_cli.control import rollout
    from aoc_cli.envs import make_env

    session = open_session(maze, config=ControllerConfig(epsilon=0.1), seed=0)
    env = make_env("maze")
    policy = make_baseline("zero", session, env)
    seen = []
    decide = policy.decide

    def recording(*args, **kw):
        seen.append((torch.get_num_threads(), faiss.omp_get_max_threads()))
        return decide(*args, **kw)

    policy.decide = recording
    rollout(session, env, 1, policy=policy)
    assert seen and set(seen) == {(1, 1)}
    assert (torch.get_num_threads(), faiss.omp_get_max_threads()) == (2, 2)


def test_train_threads_hold_for_the_neighbourhoods_search_too(tmp_path, two_threads,
                                                              monkeypatch):
    """``aoc train --threads 1`` on a log without repeats: rule 7's FQE over the log's
    neighbourhoods (FAISS searches, numpy) runs before the belief trains, on one thread
    too; the caller's pools are given back."""
    import aoc_cli
    import aoc_cli.belief.targets as targets

    store = Store(tmp_path)
    store.write("c", collect("icu-cohort", episodes=60, seed=0)[0])
    seen, original = [], targets.neighbourhood_values

    def recording(*args, **kwargs):
        seen.append((torch.get_num_threads(), faiss.omp_get_max_threads()))
        return original(*args, **kwargs)
    monkeypatch.setattr(targets, "neighbourhood_values", recording)
    # (no_select: rule 6's choice of the controller, FQE ensembles, is not what this tests)
    aoc_cli.train("c", store=tmp_path, no_select=True,
                  belief={"threads": 1, "max_epochs": 1, "hidden": 8})
    assert seen == [(1, 1)]
    assert (torch.get_num_threads(), faiss.omp_get_max_threads()) == (2, 2)
