"""AOC rows whose belief is trained on something else than the paper's value regression
(``aoc train --belief``, aoc_cli/belief/kinds.py): each runs AOC with its own model and index,
beside ``aoc`` (the paper's objective) on the same corpus and episode seeds.

* ``aoc-dynamics``: the value belief plus the auxiliary o' - o head (``--belief dynamics``);
* ``aoc-critic``: the last hidden layer of an offline TD3+BC critic (``--belief critic``, the
  paper's reference code's AOC);
* ``aoc-reward``: a model of the immediate reward (``--belief reward``, the reference code's
  "mb" variant);
* ``aoc-gamma0.9``: the paper's value belief (``--belief value``) on the return-to-go at
  gamma 0.9 instead of 0.99 (``aoc train --gamma 0.9``), which balances pendulum-het's
  upright start where gamma 0.99 does not (docs/notes/belief.md, "Upright at 100k").

The controller and its settings are the same for every row; only the beliefs (and so the hulls
and residuals) differ, and for ``aoc-gamma0.9`` also the values v^c (the index stores the
values its model was trained on: the return-to-go at gamma 0.9).
"""

from __future__ import annotations

from aoc_cli.experiments.common import belief_config, session

#: bench row -> the model id it runs with.
BELIEF_ROWS = {"aoc-dynamics": "dynamics", "aoc-critic": "critic", "aoc-reward": "reward",
               "aoc-gamma0.9": "value-gamma0.9"}
#: model id -> its BeliefConfig fields beyond the scale's (the id is the --belief otherwise).
MODEL_SETTINGS = {"value-gamma0.9": {"belief": "value", "gamma": 0.9}}
#: Gradient steps of the critic when a scale does not say (``critic_steps``).
CRITIC_STEPS = 10_000


def model_config(scale: dict, kind: str, seed: int):
    """The BeliefConfig of model ``kind`` (a --belief, or a model id of MODEL_SETTINGS) at
    ``scale``."""
    extra = dict(MODEL_SETTINGS.get(kind, {"belief": kind}))
    if kind == "critic":
        extra["critic_steps"] = int(scale.get("critic_steps", CRITIC_STEPS))
    return belief_config(scale, "value", seed, **extra)


def prepare_beliefs(ctx, scale: dict, corpus, methods, seed: int) -> None:
    """Train (or reuse) the model and index of every belief row among ``methods``."""
    for method in methods:
        kind = BELIEF_ROWS.get(method)
        if kind is not None:
            ctx.artefacts.model(corpus, kind, model_config(scale, kind, seed))
            ctx.artefacts.index(corpus, kind)


def belief_session(ctx, method: str, corpus, env, seed: int):
    """The AOC session of belief row ``method`` (its own model and index)."""
    return session(corpus, env, model_id=BELIEF_ROWS[method], seed=seed,
                   **ctx.aoc_config)
