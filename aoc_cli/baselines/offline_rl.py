"""Black-box offline RL from d3rlpy (the ``bench`` extra): TD3+BC, CQL, BCQ and BC.

The paper's "model-free RL" baseline is TD3 with a recurrent context encoder. aoc uses the
offline-RL algorithms of d3rlpy 2.8 rather than a home-made copy:

* TD3+BC (Fujimoto and Gu 2021), ``d3rlpy.algos.TD3PlusBCConfig``: the TD3 actor objective
  plus a behaviour-cloning term,
  ``pi = argmax_pi E_{(s, a) in D} [ lambda Q(s, pi(s)) - (pi(s) - a)^2 ]``,
  ``lambda = alpha / mean|Q|`` with alpha = 2.5;
* CQL (Kumar et al. 2020), ``d3rlpy.algos.CQLConfig`` (``DiscreteCQLConfig`` for discrete
  actions): soft actor-critic whose critic is pushed down on out-of-data actions,
  ``min_Q  alpha E_s[ log sum_a exp Q(s, a) - E_{a ~ D} Q(s, a) ] + TD error``;
* BCQ (Fujimoto et al. 2019), ``d3rlpy.algos.DiscreteBCQConfig`` for discrete actions (Q
  learning restricted to the actions an imitation head gives at least ``tau`` times the
  likeliest one's probability), ``BCQConfig`` for continuous ones;
* BC, ``d3rlpy.algos.DiscreteBCConfig`` (``BCConfig`` for continuous actions) at d3rlpy's
  defaults: a classifier (regressor) of the logged action, for ``aoc bench icu-cohort`` (the
  ``bc`` baseline of ``aoc rollout`` is the imitation-mode belief model, :mod:`.bc`).

The agents' state is the same context AOC sees: the standardised observation and the flattened,
standardised history of the previous L transitions (see :mod:`aoc_cli.baselines.features`), so
both can tell the pendulum's two systems apart. Actions are min-max scaled to [-1, 1] by
d3rlpy. Models are trained in the process that uses them (no file is written).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from aoc_cli.baselines.common import ActionSpace, require
from aoc_cli.baselines.features import RawFeatures
from aoc_cli.errors import AocError
from aoc_cli.settings import Settings, setting
from aoc_cli.threads import thread_limits

ALGOS = ("td3bc", "cql", "bcq", "bc")
#: The discrete agents' settings where d3rlpy's defaults are Atari's (learning rate 6.25e-5, the
#: target network copied every 8,000 steps): with a bench budget of 5,000-20,000 steps the
#: target would be copied 0-2 times, too few to carry a return through episodes of ~10 steps.
DISCRETE = {"learning_rate": 3e-4, "target_update_interval": 1000}


@dataclass(frozen=True)
class OfflineRLConfig(Settings):
    """Training budget of the d3rlpy agents (d3rlpy's own defaults otherwise).

    ``steps`` gradient steps of batch ``batch_size``; the papers train 1M steps (TD3+BC) on
    D4RL, the bench uses far fewer (see docs/results/README.md for what that costs).
    """

    label = "offline RL"

    steps: int = setting(20_000, bounds=">= 1", help="Gradient steps.")
    batch_size: int = setting(256, bounds=">= 1", help="Mini-batch rows.")
    gamma: float = setting(0.99, bounds="[0, 1]", help="Discount.")
    seed: int = setting(0, help="Seed of the agent.")
    threads: int = setting(2, bounds=">= 1", help="Torch threads while training.")


def quiet_d3rlpy() -> None:
    """d3rlpy logs every epoch through structlog to stdout, which must carry only data: keep
    warnings and errors, on stderr."""
    import logging
    import sys

    import structlog

    structlog.configure(wrapper_class=structlog.make_filtering_bound_logger(logging.WARNING),
                        logger_factory=structlog.PrintLoggerFactory(sys.stderr))


def corpus_dataset(corpus, features: RawFeatures):
    """The corpus as a d3rlpy MDPDataset whose observations are the raw context features."""
    d3rlpy = require("d3rlpy", "td3bc/cql")
    quiet_d3rlpy()
    obs = features.corpus_features(corpus)
    n = corpus.n_rows
    rewards = corpus.rewards
    if rewards is None:
        raise AocError(f"corpus {corpus.name!r} has no rewards: offline RL needs them")
    terminals = np.asarray(corpus.read("terminals"), bool).copy()
    timeouts = np.asarray(corpus.read("truncations"), bool).copy()
    last = corpus.episode_starts[1:] - 1
    timeouts[last] |= ~terminals[last]          # every episode ends with a flag
    inner = np.ones(n, bool)
    inner[last] = False
    terminals &= ~inner
    timeouts &= ~inner
    actions = np.asarray(corpus.actions)
    if corpus.discrete:
        space = d3rlpy.constants.ActionSpace.DISCRETE
        actions = actions.astype(np.int64)
    else:
        space = d3rlpy.constants.ActionSpace.CONTINUOUS
        actions = actions.astype(np.float32).reshape(n, -1)
    return d3rlpy.dataset.MDPDataset(
        observations=obs, actions=actions, rewards=np.asarray(rewards, np.float32),
        terminals=terminals.astype(np.float32), timeouts=timeouts.astype(np.float32),
        action_space=space,
        action_size=int(corpus.n_actions) if corpus.discrete else int(actions.shape[1]))


def train_agent(algo: str, corpus, history_length: int, config: OfflineRLConfig,
                bounds: tuple[np.ndarray, np.ndarray] | None = None, progress=None):
    """Train a d3rlpy ``algo`` (td3bc | cql | bcq | bc) on ``corpus`` with ``config.threads`` torch
    threads (for the fit only, aoc_cli.threads); returns (agent, features)."""
    d3rlpy = require("d3rlpy", algo)

    quiet_d3rlpy()
    if algo not in ALGOS:
        raise AocError(f"unknown offline RL algorithm {algo!r}: use {', '.join(ALGOS)}")
    if algo == "td3bc" and corpus.discrete:
        raise AocError("td3bc needs continuous actions; use the cql baseline for a discrete "
                       "action space")
    with thread_limits(torch=max(1, int(config.threads))):
        return _fit_agent(d3rlpy, algo, corpus, history_length, config, bounds, progress)


def _fit_agent(d3rlpy, algo: str, corpus, history_length: int, config: OfflineRLConfig,
               bounds, progress):
    d3rlpy.seed(int(config.seed))
    features = RawFeatures.fit(corpus, history_length, with_action=False)
    dataset = corpus_dataset(corpus, features)
    common = {"batch_size": config.batch_size, "gamma": config.gamma}
    if not corpus.discrete:
        low, high = bounds if bounds is not None else (corpus.actions.min(0), corpus.actions.max(0))
        common["action_scaler"] = d3rlpy.preprocessing.MinMaxActionScaler(
            minimum=np.asarray(low, np.float32).reshape(-1),
            maximum=np.asarray(high, np.float32).reshape(-1))
    if algo == "td3bc":
        agent = d3rlpy.algos.TD3PlusBCConfig(**common).create(device="cpu:0")
    elif algo == "bc":
        bc = d3rlpy.algos.DiscreteBCConfig if corpus.discrete else d3rlpy.algos.BCConfig
        agent = bc(**common).create(device="cpu:0")
    elif algo == "bcq" and not corpus.discrete:
        agent = d3rlpy.algos.BCQConfig(**common).create(device="cpu:0")
    elif corpus.discrete:
        discrete = d3rlpy.algos.DiscreteBCQConfig if algo == "bcq" else \
            d3rlpy.algos.DiscreteCQLConfig
        agent = discrete(**common, **DISCRETE).create(device="cpu:0")
    else:
        agent = d3rlpy.algos.CQLConfig(**common).create(device="cpu:0")

    def callback(_algo, epoch, total_step):
        if progress is not None:
            progress(total_step, config.steps)

    agent.fit(dataset, n_steps=int(config.steps),
              n_steps_per_epoch=max(1, min(int(config.steps), 1000)),
              logger_adapter=d3rlpy.logging.NoopAdapterFactory(), show_progress=False,
              save_interval=10**9, callback=callback)
    return agent, features


class OfflineRLPolicy:
    """A trained d3rlpy agent acting on the context features (module docstring)."""

    def __init__(self, algo: str, session, env=None, seed: int = 0,
                 config: OfflineRLConfig | None = None, agent=None, progress=None):
        self.name = algo
        self.actions = ActionSpace(session, env)
        config = config or OfflineRLConfig(seed=seed)
        self.threads = max(1, int(config.threads))
        if agent is None:
            if progress is not None:
                progress(0, config.steps, f"training {algo} (d3rlpy) on corpus "
                                          f"{session.corpus.name!r}")
            bounds = None if self.actions.discrete else (self.actions.low, self.actions.high)
            agent, features = train_agent(algo, session.corpus, session.model.history_length,
                                          config, bounds, progress)
        else:
            agent, features = agent
        self.agent, self.features = agent, features

    def decide(self, observation, history):
        """The agent's action, with ``config.threads`` torch threads (as it was trained)."""
        x = self.features.transform(np.asarray(observation, np.float32).reshape(1, -1), None,
                                    history)
        with thread_limits(torch=self.threads):
            action = np.asarray(self.agent.predict(x))[0]
        return self.actions.clip(action)
