"""What every baseline shares: the action bounds, the K candidates, the corpus values."""

from __future__ import annotations

import numpy as np

from aoc_cli.control.rule import action_bounds, candidate_actions
from aoc_cli.errors import AocError, call


class MissingExtra(AocError):
    """An optional package of the ``bench`` extra is not installed."""


def require(module: str, method: str):
    """Import ``module`` or raise :class:`MissingExtra` saying how to install it."""
    import contextlib
    import importlib
    import io

    try:
        # d3rlpy imports the old gym package, which prints a deprecation banner on import.
        with contextlib.redirect_stderr(io.StringIO()), contextlib.redirect_stdout(io.StringIO()):
            return importlib.import_module(module)
    except ImportError:
        raise MissingExtra(f"the {method} baseline needs the package {module!r}: run "
                           "`pip install -e .[bench]`") from None


class ActionSpace:
    """The corpus's action space at control time: bounds of a box, or n discrete actions."""

    def __init__(self, session, env=None):
        corpus = session.corpus
        self.discrete = bool(corpus.discrete)
        self.n_actions = corpus.n_actions
        if self.discrete:
            self.low = self.high = None
            self.dim = 1
        else:
            space = session.action_space or corpus.action_space
            self.low, self.high = action_bounds(space, corpus.actions)
            if env is not None and hasattr(env.action_space, "low"):
                low = np.asarray(env.action_space.low, np.float64).reshape(-1)
                high = np.asarray(env.action_space.high, np.float64).reshape(-1)
                if low.shape == self.low.shape and np.all(np.isfinite(low)) \
                        and np.all(np.isfinite(high)):
                    self.low, self.high = low, high
            self.dim = len(self.low)

    def neutral(self):
        """The neutral action: 0 (discrete), zeros when inside the box, else the box centre."""
        if self.discrete:
            return 0
        zero = np.zeros(self.dim)
        if np.all(self.low <= zero) and np.all(zero <= self.high):
            return zero
        return (self.low + self.high) / 2.0

    def uniform(self, rng: np.random.Generator, count: int) -> np.ndarray:
        """(count, d_a) uniform in the box, or (count,) int uniform over the actions."""
        if self.discrete:
            return rng.integers(0, int(self.n_actions), size=count)
        return rng.uniform(self.low, self.high, size=(count, self.dim))

    def candidates(self, rng: np.random.Generator, count: int) -> np.ndarray:
        """The controller's candidates: K uniform in a box, or every discrete action."""
        return candidate_actions(rng, count, self.low, self.high,
                                 self.n_actions if self.discrete else None)

    def clip(self, action):
        """Clip a continuous action into the box; pass a discrete one through as an int."""
        if self.discrete:
            return int(np.asarray(action).reshape(-1)[0])
        return np.clip(np.asarray(action, np.float64).reshape(-1), self.low, self.high)


def corpus_values(session, method: str) -> np.ndarray:
    """(N,) the value v^c of every corpus row, as the AOC session's model defines it."""
    values = session.index.values
    if values is None:
        raise AocError(f"the {method} baseline needs row values: use a value-mode model "
                       f"(`{call('train', session.corpus.name)}`), not an imitation-mode one")
    return np.asarray(values, np.float64)
