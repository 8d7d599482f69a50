"""The direct method of offline policy evaluation: fitted Q evaluation by d3rlpy's
``DiscreteFQE`` (the optional ``bench`` extra), for a policy known only at the logged steps.

d3rlpy's FQE regresses Q(s_t, a_t) on r_t + gamma Q'(s_{t+1}, pi(s_{t+1})) and asks the
evaluated algorithm for pi(s_{t+1}) (``algo.impl.predict_best_action``). aoc's policies are
decisions at logged steps (they may depend on the history, and a stochastic one is a
distribution per step), so the mini-batches are drawn here (numpy, one draw of B transitions
instead of d3rlpy's per-transition sampler) and the next action of each drawn transition is
the evaluated policy's at the next logged step, handed to FQE through :class:`_NextActions`;
a stochastic policy's next action is drawn from its distribution there (an unbiased target).
The update itself is d3rlpy's (``DiscreteFQE.update``, :meth:`FQEFit.train`). The last step
of an ended episode is terminal; that of a truncated one is censored (never drawn: its next
state is not in the log; :func:`fqe_policies`).

``aoc evaluate`` runs :func:`fqe_policies`: every policy's fit, then every refit, trained at
once as a batched ensemble of d3rlpy's networks (:mod:`aoc_cli.ope.ensemble`; each
member equal to its own ``DiscreteFQE.update`` training to float rounding, checked by
tests/ope/test_ope_ensemble.py), ~2x less CPU than one fit after another.

Shapes: observations (N, d_o) float, ``policy`` (N, n) probabilities of the evaluated policy
at each logged step (one-hot for a deterministic one), actions (N,) int, rewards (N,),
``starts`` (E + 1,). :func:`fit_fqe` returns ``q`` (N, n): Q_hat(s_t, a) for every action.
"""

from __future__ import annotations

import copy

import numpy as np

from aoc_cli.errors import AocError
from aoc_cli.ope.ensemble import FQEEnsemble, joined, sampler
from aoc_cli.ope.estimators import censoring_weights
from aoc_cli.ope.parts import train_parts

#: FQE settings: mini-batch, learning rate, target network sync, hidden layers.
BATCH = 256
LEARNING_RATE = 1e-3
TARGET_UPDATE = 100
HIDDEN = (64, 64)
#: Target syncs per step of the log's horizon (:func:`default_steps`), and the most steps: chosen
#: on icu-sepsis's held-out logs 0-4 by the convergence of the estimates as the steps double
#: (docs/results.md, "FQE's steps").
SYNCS_PER_STEP = 2.5
MAX_STEPS = 12000
#: The bootstrap of refits (:func:`bootstrap_fqe`): how many, and the share of the full fit's
#: steps each takes (``steps // REFIT_SHARE``).
REFITS = 10
REFIT_SHARE = 5
#: The learning rate over the fit and over each refit of :func:`fqe_policies`: annealed to 0
#: (cosine), so that a fit ends on its weights' average course rather than on one noisy step
#: (chosen on the behaviour policy, whose FQE should equal the log's mean return:
#: docs/results.md, "icu-sepsis: offline policy evaluation").
SCHEDULE = "cosine"


def available() -> str | None:
    """None when d3rlpy is importable, else the one-line reason the FQE row is absent."""
    import contextlib
    import io

    try:
        # d3rlpy imports the old gym package, which prints a deprecation banner on import
        with contextlib.redirect_stderr(io.StringIO()), contextlib.redirect_stdout(io.StringIO()):
            import d3rlpy  # noqa: F401
    except ImportError:
        return "fqe: d3rlpy is not installed (pip install -e '.[bench]'), no direct method"
    return None


class _NextActions:
    """The 'algorithm' d3rlpy's FQE evaluates: it returns the next actions of the batch being
    updated (set by :func:`fit_fqe` before each update)."""

    def __init__(self):
        self.actions = None
        self.impl = self

    def predict_best_action(self, x):
        import torch

        if self.actions is None or len(self.actions) != x.shape[0]:
            raise AocError("FQE asked for next actions of a batch it was not given")
        return torch.as_tensor(self.actions, dtype=torch.long, device=x.device)


def horizon(starts: np.ndarray, gamma: float = 1.0) -> int:
    """How many steps a value must travel back in the log: the 99th percentile of its
    episodes' lengths (``starts`` (E + 1,)), no more than the steps within which gamma's
    discount falls to 1% (gamma < 1)."""
    lengths = np.diff(np.asarray(starts, np.int64))
    h = float(np.percentile(lengths, 99)) if len(lengths) else 1.0
    if gamma < 1.0:
        h = min(h, np.log(0.01) / np.log(max(float(gamma), 1e-6)))
    return max(1, int(np.ceil(h)))


def default_steps(n_rows: int, starts: np.ndarray | None = None, gamma: float = 1.0,
                  target_update: int = TARGET_UPDATE) -> int:
    """Gradient steps: about 30 passes over the log, and at least :data:`SYNCS_PER_STEP`
    target syncs (one every ``target_update`` steps) per step of the log's :func:`horizon`
    (FQE moves a value one step back per target sync: too few and Q_hat stays between its
    start, 0, and the fixed point, low for a policy whose value lies far ahead;
    docs/results.md "FQE's steps"), between 1,500 and :data:`MAX_STEPS`."""
    steps = 30 * n_rows // BATCH
    if starts is not None:
        syncs = int(np.ceil(SYNCS_PER_STEP * horizon(starts, gamma)))
        steps = max(steps, syncs * int(target_update))
    return int(np.clip(steps, 1500, MAX_STEPS))


class FQEFit:
    """One DiscreteFQE model of ``policy`` on the log, trained by :meth:`train` (module
    docstring); :meth:`snapshot` / :meth:`restore` keep and put back its weights and optimiser
    state (a bootstrap refit starts from the full fit: :func:`bootstrap_fqe`). With
    ``cosine_steps``, d3rlpy's Adam anneals its learning rate to 0 over that many updates
    (d3rlpy's CosineAnnealingLRFactory: the ensemble's "cosine" schedule)."""

    def __init__(self, observations, actions, rewards, starts, policy, gamma: float = 1.0,
                 seed: int = 0, batch: int = BATCH, learning_rate: float = LEARNING_RATE,
                 target_update: int = TARGET_UPDATE, cosine_steps: int | None = None):
        reason = available()
        if reason is not None:
            raise AocError(reason)
        # d3rlpy is the optional bench extra, torch a heavy import: both only when FQE runs
        import d3rlpy
        import torch
        from d3rlpy.models.encoders import VectorEncoderFactory
        from d3rlpy.ope import DiscreteFQE, FQEConfig
        from d3rlpy.optimizers import AdamFactory
        from d3rlpy.optimizers.lr_schedulers import CosineAnnealingLRFactory

        obs = np.asarray(observations, np.float64)
        mu, sd = obs.mean(0), obs.std(0)
        self.x = ((obs - mu) / np.where(sd > 0, sd, 1.0)).astype(np.float32)   # (N, d_o)
        self.n_rows, self.n_actions = np.asarray(policy).shape
        self.act = np.asarray(actions, np.int64)
        self.rew = np.asarray(rewards, np.float32)
        self.starts = np.asarray(starts, np.int64)
        self.last = np.zeros(self.n_rows, bool)
        self.last[self.starts[1:] - 1] = True
        self.nxt = np.where(self.last, np.arange(self.n_rows), np.arange(self.n_rows) + 1)
        self.cum = cumulative(policy)
        self.batch = batch
        d3rlpy.seed(seed)
        torch.manual_seed(seed)
        self.algo = _NextActions()
        self.fqe = DiscreteFQE(algo=self.algo, config=FQEConfig(
            batch_size=batch, gamma=float(gamma), learning_rate=learning_rate,
            target_update_interval=target_update,
            optim_factory=AdamFactory() if cosine_steps is None else AdamFactory(
                lr_scheduler_factory=CosineAnnealingLRFactory(T_max=int(cosine_steps))),
            encoder_factory=VectorEncoderFactory(hidden_units=list(HIDDEN))), device=False)
        self.fqe.create_impl((self.x.shape[1],), self.n_actions)
        self.rng = np.random.default_rng(seed)

    def train(self, steps: int, rows: np.ndarray | None = None, progress=None) -> None:
        """``steps`` updates on mini-batches drawn from ``rows`` (a multiset of row indices:
        a resampled log; None: every row once)."""
        from d3rlpy.dataset import TransitionMiniBatch

        batch, one = self.batch, np.ones((self.batch, 1), np.float32)
        pool = None if rows is None else np.asarray(rows, np.int64)
        for step in range(int(steps)):
            if pool is None:
                idx = self.rng.integers(0, self.n_rows, batch)
            else:
                idx = pool[self.rng.integers(0, len(pool), batch)]
            j = self.nxt[idx]
            # the evaluated policy's action at the next logged step (drawn if it is stochastic)
            self.algo.actions = (self.cum[j] < self.rng.random((batch, 1))).sum(1).clip(
                0, self.n_actions - 1)
            self.fqe.update(TransitionMiniBatch(
                observations=self.x[idx], actions=self.act[idx, None].astype(np.float32),
                rewards=self.rew[idx, None], next_observations=self.x[j],
                next_actions=np.zeros((batch, 1), np.float32),
                terminals=self.last[idx, None].astype(np.float32), intervals=one,
                transitions=[]))
            if progress is not None and (step + 1) % 500 == 0:
                progress(step + 1, steps)

    def snapshot(self) -> dict:
        """A copy of the model's weights, target weights and optimiser state."""
        m = self.fqe.impl.modules
        return copy.deepcopy({"q": m.q_funcs.state_dict(), "target": m.targ_q_funcs.state_dict(),
                              "optim": m.optim.state_dict()})

    def restore(self, state: dict) -> None:
        """Put back a :meth:`snapshot` (or an ensemble member's state, with its step count)."""
        m = self.fqe.impl.modules
        if "count" in state:
            self.fqe._grad_step = int(state["count"])
        m.q_funcs.load_state_dict(state["q"])
        m.targ_q_funcs.load_state_dict(state["target"])
        m.optim.load_state_dict(copy.deepcopy(state["optim"]))

    def q(self, rows: np.ndarray | None = None) -> np.ndarray:
        """(len(rows), n) Q_hat of the given rows (None: every row) and every action."""
        x = self.x if rows is None else self.x[np.asarray(rows, np.int64)]
        return q_table(self.fqe, x, self.n_actions)

    def distinct(self) -> tuple:
        """(the distinct standardised observations (U, d_o), each row's index among them
        (N,)), found once (rows compared as bytes: one sort)."""
        if getattr(self, "_distinct", None) is None:
            rows = np.ascontiguousarray(self.x).view(
                np.dtype((np.void, self.x.dtype.itemsize * self.x.shape[1]))).ravel()
            _, first, of = np.unique(rows, return_index=True, return_inverse=True)
            self._distinct = (self.x[first], np.asarray(of, np.int64).reshape(-1))
        return self._distinct


def fit_fqe(observations, actions, rewards, starts, policy, gamma: float = 1.0,
            steps: int | None = None, seed: int = 0, progress=None, batch: int = BATCH,
            learning_rate: float = LEARNING_RATE, target_update: int = TARGET_UPDATE
            ) -> np.ndarray:
    """Q_hat (N, n) of ``policy`` by d3rlpy's DiscreteFQE on the log (module docstring).
    Observations are standardised here (by the log's mean and spread) before d3rlpy sees
    them. ``progress(done, total)`` after each block of steps."""
    fit = FQEFit(observations, actions, rewards, starts, policy, gamma, seed, batch,
                 learning_rate, target_update)
    total = default_steps(fit.n_rows, starts, gamma, target_update) if steps is None \
        else int(steps)
    fit.train(total, progress=progress)
    return fit.q()


def refit_steps(steps: int) -> int:
    """Gradient steps of one bootstrap refit: a fifth of the full fit's, at least 300."""
    return max(300, int(steps) // REFIT_SHARE)


def bootstrap_fqe(observations, actions, rewards, starts, policy, gamma: float = 1.0,
                  steps: int | None = None, refits: int = REFITS, refit_step_count:
                  int | None = None, seed: int = 0, progress=None) -> dict:
    """:func:`fqe_policies` of one policy."""
    return fqe_policies(observations, actions, rewards, starts, [policy], gamma, steps, refits,
                        refit_step_count, seed, progress)[0]


def fqe_policies(observations, actions, rewards, starts, policies: list, gamma: float = 1.0,
                 steps: int | None = None, refits: int = REFITS,
                 refit_step_count: int | None = None, seed: int = 0, progress=None,
                 schedule: str = SCHEDULE, behaviour: bool = False,
                 n_actions: int | None = None, parts: int | None = None,
                 truncated: np.ndarray | None = None) -> list:
    """The direct method for each of P policies on one log, with an interval that holds the
    fitted model's own error. Per policy: Q_hat (N, n) of the full fit, its estimate (the mean
    start value of the policy), and ``refits`` refits, each on the log's episodes resampled
    with replacement, started from the full fit's weights and trained ``refit_step_count``
    more steps on the resample (a warm-started bootstrap: a refit from scratch costs the full
    fit again, ``refits`` times). Each refit's replicate is its resample's mean start value.
    With refits, the estimate is the refits' mean start value over the whole log's episodes
    (bagged: one fit's value moves with its training noise, ~0.01 on icu-sepsis, and the mean
    of 10 refits less; chosen on the behaviour policy, whose FQE should equal the log's mean
    return: docs/results.md), the interval that +- :func:`student_quantile` x the replicates'
    standard deviation (a normal bootstrap interval, Student's t for the few replicates whose
    spread it estimates: 2.26 for 10 refits; their percentiles would be their extremes);
    without, the full fit's mean start value (``fit_estimate`` either way). The P fits train
    as one ensemble, then the P x ``refits`` refits as another
    (:class:`aoc_cli.ope.ensemble.FQEEnsemble`: each member d3rlpy's DiscreteFQE
    update, batched); every policy's fit starts from the same d3rlpy initialisation and
    the policies' refits see the same resamples. ``progress(done, total)`` in member-steps;
    ``schedule`` the learning rate's over the fit and over each refit
    (:meth:`aoc_cli.ope.ensemble.FQEEnsemble.train`); ``parts`` the processes each
    ensemble trains in (:func:`aoc_cli.ope.parts.train_parts`; None: the cores, at
    most 4): the same values in any number.
    Returns per policy {"q" (the full fit's), "estimate", "fit_estimate", "low", "high",
    "replicates" (refits,), "counts" (refits, E) (each refit's resampled episodes: a paired
    difference with another estimate over the same resamples), "bagged", "steps",
    "refit_steps", "seconds"}.

    ``behaviour``: one more member in the fit's ensemble, the logged behaviour (the next
    action the log's own: SARSA; ``n_actions`` actions when no policy is given), no refits, drawing its mini-batches from its own
    generator (seeded by ``seed``), so that its Q_hat is the same whatever policies train
    beside it (:func:`behaviour_fqe` alone); its record, last in the list, holds "q" (N, n),
    "logged" (N,) Q_hat of each logged step, "estimate" (the mean Q_hat of the episodes' first
    logged steps: the behaviour's value, which the log's mean return also estimates), "steps".

    ``truncated`` (E,): episodes cut short (:func:`aoc_cli.ope.estimators.censoring_weights`): the last step of one is
    never drawn, and the transitions that continue are drawn in proportion to the inverse of
    their chance to have escaped the cut."""
    import time

    started = time.perf_counter()
    policies = [np.asarray(p, np.float64) for p in policies]
    P = len(policies)
    act = np.asarray(actions, np.int64).reshape(-1)
    logged = None
    if behaviour:                   # the logged actions as a policy (N, n): one-hot
        logged = np.zeros((len(act), policies[0].shape[1] if P else int(n_actions)))
        logged[np.arange(len(act)), act] = 1.0
    fit = FQEFit(observations, act, rewards, starts, policies[0] if P else logged, gamma, seed)
    cums = np.stack([fit.cum] + [cumulative(p) for p in policies[1:]]) if P else None
    M = P + (logged is not None)
    total = default_steps(fit.n_rows, starts, gamma, fit.fqe.config.target_update_interval) \
        if steps is None else int(steps)
    k = refit_steps(total) if refit_step_count is None else int(refit_step_count)
    grand = M * total + (P * refits * k if refits > 1 else 0)
    tick = (lambda base, m: None) if progress is None else \
        (lambda base, m: lambda done: progress(base + m * done, grand))
    behaviour_seed = [seed, 1]
    weights = None if truncated is None or not np.any(truncated) else \
        censoring_weights(fit.starts, truncated)

    def fit_draw(keep, rng):        # members keep of [policies..., behaviour]: their draws
        draws = [] if not P else [sampler(fit, cums, np.arange(P), [None] * P, rng, P,
                                          keep=keep[keep < P], weights=weights)]
        if logged is not None and np.any(keep == P):
            draws.append(sampler(fit, cumulative(logged)[None], np.zeros(1, np.int64),
                                 [None], np.random.default_rng(behaviour_seed), 1,
                                 weights=weights))
        return joined(*draws)

    ens = FQEEnsemble(fit, [fit.snapshot()] * M, [fit.fqe._grad_step] * M)
    train_parts(ens, total, fit_draw, fit.rng, parts, progress=tick(0, M), schedule=schedule)
    first = fit.starts[:-1]
    n_episodes = len(first)
    q = ens.q()                                                             # (M, N, n)
    fitted = [float(np.mean((policies[i][first] * q[i][first]).sum(1))) for i in range(P)]
    out = [{"q": q[i], "estimate": fitted[i], "fit_estimate": fitted[i], "low": float("nan"),
            "high": float("nan"), "replicates": np.empty(0), "bagged": float("nan"),
            "steps": total, "refit_steps": 0} for i in range(P)]
    if refits > 1:
        lengths = np.diff(fit.starts)
        rng = np.random.default_rng(seed + 1)
        counts = rng.multinomial(n_episodes, np.full(n_episodes, 1.0 / n_episodes),
                                 size=refits)                               # (refits, E)
        pools = []
        for c in counts:
            chosen = np.repeat(np.arange(n_episodes), c)                    # resampled episodes
            pools.append(np.repeat(fit.starts[chosen], lengths[chosen]) + _offsets(lengths[chosen]))
        boot = ens.repeat(refits, range(P))             # member i * refits + b: policy i, refit b
        policy_of, boot_pools = np.repeat(np.arange(P), refits), pools * P
        train_parts(boot, k, lambda keep, rng: sampler(fit, cums, policy_of, boot_pools, rng,
                                                       P * refits, keep=keep,
                                                       weights=weights),
                    fit.rng, parts, progress=tick(M * total, P * refits), schedule=schedule)
        q0 = boot.q(first).reshape(P, refits, n_episodes, -1)               # (P, refits, E, n)
        quantile = student_quantile(refits - 1)
        for i, rec in enumerate(out):
            v0 = (policies[i][first][None] * q0[i]).sum(2)                  # (refits, E)
            reps = (counts * v0).sum(1) / n_episodes
            half = quantile * float(np.std(reps, ddof=1))
            bagged = float(v0.mean())
            rec.update(estimate=bagged, low=bagged - half, high=bagged + half, replicates=reps,
                       bagged=bagged, refit_steps=k, counts=counts)
    if logged is not None:
        at = q[P][np.arange(fit.n_rows), act]                              # (N,)
        out.append({"q": q[P], "logged": at, "estimate": float(np.mean(at[first])),
                    "steps": total})
    seconds = time.perf_counter() - started
    for rec in out:
        rec["seconds"] = seconds
    return out


def behaviour_fqe(observations, actions, rewards, starts, n_actions: int, gamma: float = 1.0,
                  steps: int | None = None, seed: int = 0, progress=None,
                  schedule: str = SCHEDULE, truncated: np.ndarray | None = None) -> dict:
    """The behaviour's record of :func:`fqe_policies` (``behaviour=True``) with no policy
    beside it: the same Q_hat as when it trains beside policies (its own draws, the same
    initialisation), to float rounding."""
    return fqe_policies(observations, actions, rewards, starts, [], gamma, steps, 0, seed=seed,
                        progress=progress, schedule=schedule, behaviour=True,
                        n_actions=n_actions, truncated=truncated)[-1]


def student_quantile(df: int) -> float:
    """The 97.5% quantile of Student's t with ``df`` degrees of freedom: the half-width, in
    standard deviations, of a 95% interval whose standard deviation comes from df + 1
    replicates (1.96 for many; 2.26 for 10 refits, 4.30 for 3)."""
    from scipy.special import stdtrit  # slow to import: only where refits run

    return float(stdtrit(int(df), 0.975))


def cumulative(policy: np.ndarray) -> np.ndarray:
    """(N, n) cumulative probabilities of a policy (N, n), each row ending at 1."""
    cum = np.cumsum(np.asarray(policy, np.float64), axis=1)
    return cum / cum[:, -1:]


def _offsets(lengths: np.ndarray) -> np.ndarray:
    """(sum lengths,) 0..l-1 within each run of the given lengths."""
    ends = np.cumsum(lengths)
    return np.arange(int(ends[-1]) if len(ends) else 0) - np.repeat(ends - lengths, lengths)


def q_table(fqe, x: np.ndarray, n_actions: int, block: int = 65536) -> np.ndarray:
    """(N, n) Q_hat of every row of standardised observations ``x`` (N, d_o) and action."""
    out = np.empty((len(x), n_actions))
    rows_per = max(1, block // n_actions)
    for lo in range(0, len(x), rows_per):
        xs = x[lo:lo + rows_per]
        rep = np.repeat(xs, n_actions, axis=0)
        a = np.tile(np.arange(n_actions), len(xs))
        out[lo:lo + len(xs)] = fqe.predict_value(rep, a).reshape(len(xs), n_actions)
    return out
