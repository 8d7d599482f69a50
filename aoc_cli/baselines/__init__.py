"""Comparison controllers for `aoc rollout --policy NAME` and `aoc bench`.

>>> policy = make_baseline("knn-belief", session, env, seed=0)    # doctest: +SKIP
>>> action = policy.decide(observation, history)                  # doctest: +SKIP

Every baseline has ``decide(observation, history) -> action`` (a float array, or an int for a
discrete action space) and optionally ``reset()`` (called at each episode start). They act on
the same corpus, history length and row selection as the AOC session they are built from.

========== ===========================================================================
name       what it is
========== ===========================================================================
zero       the neutral action (zeros, the box centre, or action 0): "do nothing"
random     a uniform random action
1nn, knn   nearest-neighbour Q on raw features (o, a, flattened history), argmax over
           the K candidates, k = 1 or the controller's k (default 2 (d_b + 1))
1nn-belief the same on beliefs, in the session's own index
knn-belief
bc         behaviour cloning: the imitation-mode model ``bc`` (same history encoder)
td3bc      TD3+BC from d3rlpy (``pip install -e .[bench]``)
cql        CQL from d3rlpy (``pip install -e .[bench]``)
bcq        BCQ from d3rlpy (discrete BCQ for discrete actions; ``pip install -e .[bench]``)
mpc        MPPI (pytorch-mppi) over a learned dynamics model (``pip install -e .[bench]``)
========== ===========================================================================
"""

from __future__ import annotations

from aoc_cli.baselines.bc import BehaviourCloning
from aoc_cli.baselines.common import ActionSpace, MissingExtra
from aoc_cli.baselines.features import RawFeatures
from aoc_cli.baselines.mpc import MPCPolicy
from aoc_cli.baselines.neighbours import NearestNeighbourController, knn_k
from aoc_cli.baselines.offline_rl import OfflineRLPolicy
from aoc_cli.baselines.simple import RandomPolicy, ZeroPolicy
from aoc_cli.errors import AocError

#: name -> one-line description (the order in tables).
BASELINES = {
    "zero": "the neutral action",
    "random": "uniform random actions",
    "1nn": "nearest-neighbour Q on raw features, k = 1",
    "knn": "nearest-neighbour Q on raw features, k = 2 (d_b + 1)",
    "1nn-belief": "nearest-neighbour Q on beliefs, k = 1",
    "knn-belief": "nearest-neighbour Q on beliefs, k = 2 (d_b + 1)",
    "bc": "behaviour cloning (imitation-mode model 'bc')",
    "td3bc": "TD3+BC (d3rlpy)",
    "cql": "CQL (d3rlpy)",
    "bcq": "BCQ (d3rlpy)",
    "mpc": "MPPI over a learned dynamics model (pytorch-mppi)",
}
#: Baselines that need the optional ``bench`` extra.
EXTRA = {"td3bc": "d3rlpy", "cql": "d3rlpy", "bcq": "d3rlpy", "mpc": "pytorch_mppi"}


def make_baseline(name: str, session, env=None, seed: int = 0, **options):
    """The baseline ``name`` acting on ``session``'s corpus (see the module docstring).

    ``options`` go to the baseline's constructor (e.g. ``config=`` for td3bc/cql/mpc, a
    pre-trained ``agent=``/``model=``). Unknown name, a missing optional package (pip install
    -e .[bench]) or a missing bc model -> AocError.
    """
    if name == "zero":
        return ZeroPolicy(session, env, seed)
    if name == "random":
        return RandomPolicy(session, env, seed)
    if name in ("1nn", "knn", "1nn-belief", "knn-belief"):
        k = 1 if name.startswith("1nn") else knn_k(session)
        space = "belief" if name.endswith("-belief") else "raw"
        return NearestNeighbourController(session, env, k=k, space=space, seed=seed, name=name)
    if name == "bc":
        return BehaviourCloning(session, env, seed, **options)
    if name in ("td3bc", "cql", "bcq"):
        return OfflineRLPolicy(name, session, env, seed, **options)
    if name == "mpc":
        return MPCPolicy(session, env, seed, **options)
    raise AocError(f"unknown policy {name!r}: use aoc or one of {', '.join(BASELINES)}")


def extra_missing(name: str) -> str | None:
    """The name of the missing optional package ``name`` needs, or None when it can run."""
    import importlib.util

    module = EXTRA.get(name)
    if module is not None and importlib.util.find_spec(module) is None:
        return module
    return None


__all__ = ["BASELINES", "EXTRA", "ActionSpace", "MissingExtra", "RawFeatures", "extra_missing",
           "make_baseline"]
