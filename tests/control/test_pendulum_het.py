"""Issue 6's pendulum-het checks, on a small corpus (30k rows, the dynamics-head model).

What holds (asserted): on the paper's upright start AOC keeps the pendulum up far better than
the data's average episode, and epsilon = 1.0 (no residual filter) loses it. What does not
hold at this size (a strict xfail, so it fails the suite the day it starts passing): on the
random start AOC does not beat the data's average nor doing nothing — docs/notes/belief.md, "Why AOC
does not swing up", has the traced decisions and the data variants tried. At the paper's sizes
(100k and 300k rows, full training; docs/results/pendulum.md) the same AOC swings up to the data's level
(-392 and -449 against -376 and -374, doing nothing -1154) but not above it; those runs take 20-70
minutes each here, too long for the suite.
"""

import numpy as np
import pytest

from aoc_cli.belief import BeliefConfig, train_model
from aoc_cli.control.config import ControllerConfig
from aoc_cli.control.run import rollout
from aoc_cli.envs import collect, make_env
from aoc_cli.index import build_index
from aoc_cli.control import model_free_session, open_session
from aoc_cli.store import Store

EPISODES = 6


@pytest.fixture(scope="module")
def pendulum(tmp_path_factory):
    """(corpus, data's mean episode return): 30k rows, collect seed 0, model 'dyn' + index.
    Measured with these settings (6 episodes, seeds 100-105): data -386; upright AOC -105
    (four episodes -0.1 to -0.2, two fell: -253, -375) at epsilon 0.5, -931 at 1.0.
    Other seeds, to size the margins: model seed 1: -0.10 against -660 at 1.0; corpus seed 1:
    -187 (one episode of six fell, -1121) against -1072, the data -363."""
    import torch

    torch.set_num_threads(1)
    data, _summary = collect("pendulum-het", steps=30_000, seed=0)
    corpus = Store(tmp_path_factory.mktemp("pendulum")).write("pendulum", data)
    train_model(corpus, BeliefConfig(dynamics_weight=1.0, threads=1, max_epochs=30,
                                     patience=6), "dyn")
    build_index(corpus, "dyn")
    return corpus, float(corpus.episode_returns().mean())


def mean_return(corpus, env_id: str, epsilon: float | None = None, policy=None) -> float:
    env = make_env(env_id)
    if policy is None:
        session = open_session(corpus, "dyn", "default", ControllerConfig(epsilon=epsilon))
    else:
        from aoc_cli.baselines import make_baseline

        session = model_free_session(corpus)
        policy = make_baseline(policy, session, env)
    _results, summary = rollout(session, env, EPISODES, seed=100, policy=policy)
    return summary["return_mean"]


def test_upright_aoc_beats_the_data_and_epsilon_one_does_worse(pendulum):
    corpus, data_mean = pendulum
    aoc = mean_return(corpus, "pendulum-het-upright", epsilon=0.5)
    unfiltered = mean_return(corpus, "pendulum-het-upright", epsilon=1.0)
    assert aoc > data_mean + 100, (aoc, data_mean)
    assert unfiltered < aoc - 300, (unfiltered, aoc)


@pytest.mark.xfail(strict=True, reason="issue 6: at 30k rows AOC does not swing up; at 100k-300k "
                                        "it reaches the data's average, not above it "
                                        "(docs/notes/belief.md, docs/results/pendulum.md)")
def test_random_start_aoc_beats_the_data_and_doing_nothing(pendulum):
    corpus, data_mean = pendulum
    aoc = mean_return(corpus, "pendulum-het", epsilon=0.5)
    zero = mean_return(corpus, "pendulum-het", policy="zero")
    assert aoc > data_mean and aoc > zero + 100, (aoc, data_mean, zero)
