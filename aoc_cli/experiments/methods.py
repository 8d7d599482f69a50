"""Running one method (AOC or a baseline) for some episodes, and turning that into a result row.

Every method of one seed is evaluated on the same episode seeds (``episode_seed(seed)``), so
their start states are paired. Black-box models (TD3+BC, CQL, the MPC dynamics model) are
trained once per corpus and seed and kept in memory for the rest of the run.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

from aoc_cli.baselines import MissingExtra, extra_missing, make_baseline
from aoc_cli.baselines.mpc import MPCConfig
from aoc_cli.baselines.offline_rl import OfflineRLConfig
from aoc_cli.control import rollout
from aoc_cli.errors import AocError
from aoc_cli.progress import stage

#: Methods that are not controllers: the data's own average return.
DATA = "data"


def episode_seed(seed: int) -> int:
    """The first episode seed of bench seed ``seed`` (episodes use seed, seed + 1, ...)."""
    return 10_000 + 1_000 * int(seed)


@dataclass
class Budget:
    """Training budgets of the black-box baselines (see docs/results/README.md for the choices)."""

    offline_rl_steps: int = 20_000
    mpc_epochs: int = 30
    mpc_samples: int = 200
    mpc_horizon: int = 15
    threads: int = 1


@dataclass
class MethodRun:
    """What one method produced for one seed: the episodes, or why it was skipped."""

    method: str
    results: list = field(default_factory=list)
    summary: dict = field(default_factory=dict)
    status: str = "ok"
    note: str = ""
    seconds: float = 0.0


class Runner:
    """Runs methods on sessions; caches trained black-box models by (corpus hash, method)."""

    def __init__(self, budget: Budget | None = None, progress=None, log=None):
        self.budget = budget or Budget()
        self.progress = progress
        self.log = log or (lambda text: None)
        self.cache: dict = {}

    def _stage(self, label: str, total: int):
        """The Progress of one training or rollout (:func:`aoc_cli.progress.stage`)."""
        return stage(self.progress, label, total)

    def policy(self, method: str, session, env, seed: int):
        """The controller object of ``method`` (None for AOC itself)."""
        if method == "aoc":
            return None
        options = {}
        key = (session.corpus.hash, session.model.history_length, method, seed)
        if method in ("td3bc", "cql", "mpc"):
            b = self.budget
            if method == "mpc":
                options["config"] = MPCConfig(epochs=b.mpc_epochs, samples=b.mpc_samples,
                                              horizon=b.mpc_horizon, seed=seed,
                                              threads=b.threads)
            else:
                options["config"] = OfflineRLConfig(steps=b.offline_rl_steps, seed=seed,
                                                    threads=b.threads)
            if key in self.cache:
                options["model" if method == "mpc" else "agent"] = self.cache[key]
            else:
                options["progress"] = self._stage(
                    f"train {method} on {session.corpus.name}",
                    b.mpc_epochs if method == "mpc" else b.offline_rl_steps)
                started = time.perf_counter()
                policy = make_baseline(method, session, env, seed=seed, **options)
                self.log(f"train {method} on {session.corpus.name}: "
                         f"{time.perf_counter() - started:.1f} s")
                self.cache[key] = (policy.net, policy.features) if method == "mpc" \
                    else (policy.agent, policy.features)
                return policy
        return make_baseline(method, session, env, seed=seed, **options)

    def run(self, method: str, session, env, episodes: int, seed: int,
            noise_after: int | None = None, noise_std: float = 0.0,
            label: str = "") -> MethodRun:
        """Roll out ``method`` for ``episodes`` episodes; a missing extra -> status skipped."""
        missing = extra_missing(method)
        if missing is not None:
            return MethodRun(method, status="skipped",
                             note=f"needs {missing}: pip install -e .[bench]")
        started = time.perf_counter()
        try:
            policy = self.policy(method, session, env, seed)
        except MissingExtra as err:
            return MethodRun(method, status="skipped", note=str(err))
        try:
            results, summary = rollout(session, env, episodes, seed=episode_seed(seed),
                                       policy=policy, noise_after=noise_after,
                                       noise_std=noise_std,
                                       progress=self._stage(f"{method} {label}".strip(),
                                                            episodes))
        except (AocError, ArithmeticError, ValueError, RuntimeError) as err:
            # one failing method must not lose the others' results: reported as failed
            self.log(f"{method} {label}: failed: {type(err).__name__}: {err}")
            return MethodRun(method, status="failed", note=f"{type(err).__name__}: {err}",
                             seconds=time.perf_counter() - started)
        return MethodRun(method, results, summary, seconds=time.perf_counter() - started)


def row_values(run: MethodRun) -> dict:
    """The result-row metrics of one method run."""
    if run.status != "ok":
        return {"status": run.status, "note": run.note}
    returns = np.array([r.total_return for r in run.results], dtype=np.float64)
    successes = [r.success for r in run.results if r.success is not None]
    residuals = [r.mean_residual for r in run.results if r.mean_residual is not None]
    return {
        "episodes": len(run.results),
        "return_mean": float(returns.mean()),
        "return_std": float(returns.std()),
        "success_rate": float(np.mean(successes)) if successes else None,
        "mean_residual": float(np.mean(residuals)) if residuals else None,
        "seconds_per_step": run.summary.get("seconds_per_step"),
        "note": run.note or None,
    }


def data_values(corpus) -> dict:
    """The data's own average return: complete episodes of the corpus (the last episode of a
    corpus collected to a row budget may be cut short and is left out)."""
    returns = corpus.episode_returns()
    if returns is None or len(returns) == 0:
        raise AocError(f"corpus {corpus.name!r} has no rewards: no data return to report")
    src = (corpus.manifest.get("sources") or [{}])[-1]
    if src.get("steps") is not None and len(returns) > 1:
        lengths = np.diff(corpus.episode_starts)
        full = lengths == lengths.max() if src.get("task", "").startswith("pendulum") \
            else np.ones(len(returns), bool)
        full[-1] = False
        returns = returns[full] if full.any() else returns
    return {"episodes": int(len(returns)), "return_mean": float(np.mean(returns)),
            "return_std": float(np.std(returns))}
