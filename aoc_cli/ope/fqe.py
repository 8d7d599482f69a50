"""The direct method of offline policy evaluation: fitted Q evaluation (FQE) in plain torch, for
a policy known only at the logged steps.

FQE regresses Q(s_t, a_t) on r_t + gamma Q'(s_{t+1}, pi(s_{t+1})), Q' a target network synced
every :data:`TARGET_UPDATE` updates (Le et al. 2019; the update of d3rlpy's DiscreteFQE, the
reference of tests/ope/test_ope_ensemble.py). aoc's policies are decisions at logged steps
(they may depend on the history, and a stochastic one is a distribution per step), so the next
action of each drawn transition is the evaluated policy's at the next logged step; a
stochastic policy's next action is drawn from its distribution there (an unbiased target).
The last step of an ended episode is terminal; that of a truncated one is censored: its
target bootstraps from the value its next state is predicted to have
(:mod:`aoc_cli.ope.ensemble`).

``aoc evaluate`` runs :func:`fqe_policies`: every policy's fit, then every refit, trained at
once as a batched ensemble (:mod:`aoc_cli.ope.ensemble`), ~2x less CPU than one fit after
another.

Shapes: observations (N, d_o) float, ``policy`` (N, n) probabilities of the evaluated policy
at each logged step (one-hot for a deterministic one), actions (N,) int, rewards (N,),
``starts`` (E + 1,). :func:`fit_fqe` returns ``q`` (N, n): Q_hat(s_t, a) for every action.
"""

from __future__ import annotations

import itertools

import numpy as np

from aoc_cli.ope.ensemble import FQEEnsemble, joined, sampler
from aoc_cli.ope.parts import train_parts
from aoc_cli.rows import distinct_rows

#: FQE settings: mini-batch, learning rate, target network sync, hidden layers.
BATCH = 256
LEARNING_RATE = 1e-3
TARGET_UPDATE = 100
HIDDEN = (64, 64)
#: Target syncs per step of the log's horizon (:func:`default_steps`), and the most steps: chosen
#: on icu-sepsis's held-out logs 0-4 by the convergence of the estimates as the steps double
#: (docs/notes/results-ope.md, "FQE's steps").
SYNCS_PER_STEP = 2.5
MAX_STEPS = 12000
#: The bootstrap of refits (:func:`bootstrap_fqe`): how many, and the share of the full fit's
#: steps each takes (``steps // REFIT_SHARE``).
REFITS = 10
REFIT_SHARE = 5
#: The learning rate over the fit and over each refit of :func:`fqe_policies`: annealed to 0
#: (cosine), so that a fit ends on its weights' average course rather than on one noisy step
#: (chosen on the behaviour policy, whose FQE should equal the log's mean return:
#: docs/results/ope.md).
SCHEDULE = "cosine"


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
    docs/notes/results-ope.md "FQE's steps"), between 1,500 and :data:`MAX_STEPS`."""
    steps = 30 * n_rows // BATCH
    if starts is not None:
        syncs = int(np.ceil(SYNCS_PER_STEP * horizon(starts, gamma)))
        steps = max(steps, syncs * int(target_update))
    return int(np.clip(steps, 1500, MAX_STEPS))


class FQEFit:
    """The log as FQE trains on it, and FQE's settings: observations standardised (by the log's
    mean and spread), actions, rewards, each row's next row (itself at an episode's last),
    terminal ``last`` and censored ``cut`` steps (N,), the policy's cumulative probabilities
    ``cum``, mini-batch, gamma, target interval, learning rate, hidden layers, and a generator
    seeded by ``seed``. ``truncated`` (E,): episodes cut short (their last step censored)."""

    def __init__(self, observations, actions, rewards, starts, policy, gamma: float = 1.0,
                 seed: int = 0, batch: int = BATCH, learning_rate: float = LEARNING_RATE,
                 target_update: int = TARGET_UPDATE, hidden: tuple | None = None,
                 truncated: np.ndarray | None = None):
        obs = np.asarray(observations, np.float64)
        mu, sd = obs.mean(0), obs.std(0)
        self.x = ((obs - mu) / np.where(sd > 0, sd, 1.0)).astype(np.float32)   # (N, d_o)
        self.n_rows, self.n_actions = np.asarray(policy).shape
        self.act = np.asarray(actions, np.int64)
        self.rew = np.asarray(rewards, np.float32)
        self.starts = np.asarray(starts, np.int64)
        self.last = np.zeros(self.n_rows, bool)
        self.last[self.starts[1:] - 1] = True
        self.cut = np.zeros(self.n_rows, bool)
        if truncated is not None:
            self.cut[self.starts[1:][np.asarray(truncated, bool)] - 1] = True
        self.nxt = np.where(self.last, np.arange(self.n_rows), np.arange(self.n_rows) + 1)
        self.cum = cumulative(policy)
        self.batch, self.gamma = int(batch), float(gamma)
        self.learning_rate, self.interval = float(learning_rate), int(target_update)
        self.hidden = tuple(HIDDEN if hidden is None else hidden)
        self.seed = int(seed)
        self.rng = np.random.default_rng(seed)

    def initial(self) -> list:
        """The network's initial weights in torch's layout, [W_1 (out, in), b_1 (out,), ...]:
        ``torch.nn.Linear``'s default initialisation under ``torch.manual_seed(seed)``, layer
        by layer, the global generator left as it was. The last layer gives Q of every action,
        and with censored steps C of every action too (:mod:`aoc_cli.ope.ensemble`)."""
        import torch

        outputs = self.n_actions * (2 if self.cut.any() else 1)
        sizes = (self.x.shape[1], *self.hidden, outputs)
        with torch.random.fork_rng(devices=[]):
            torch.manual_seed(self.seed)
            layers = [torch.nn.Linear(i, o) for i, o in itertools.pairwise(sizes)]
        return [t.detach() for layer in layers for t in (layer.weight, layer.bias)]

    def distinct(self) -> tuple:
        """(the distinct standardised observations (U, d_o), each row's index among them
        (N,)), found once (rows compared as bytes: one sort)."""
        if getattr(self, "_distinct", None) is None:
            first, of = distinct_rows(self.x)
            self._distinct = (self.x[first], of)
        return self._distinct


def fit_fqe(observations, actions, rewards, starts, policy, gamma: float = 1.0,
            steps: int | None = None, seed: int = 0, progress=None, batch: int = BATCH,
            learning_rate: float = LEARNING_RATE, target_update: int = TARGET_UPDATE,
            truncated: np.ndarray | None = None, schedule: str = SCHEDULE) -> np.ndarray:
    """Q_hat (N, n) of ``policy`` by one FQE fit on the log (module docstring), the learning
    rate's ``schedule`` as :func:`fqe_policies`'s. Observations are standardised here (by the
    log's mean and spread). ``progress(done)`` every 100 steps."""
    fit = FQEFit(observations, actions, rewards, starts, policy, gamma, seed, batch,
                 learning_rate, target_update, truncated=truncated)
    total = default_steps(fit.n_rows, starts, gamma, target_update) if steps is None \
        else int(steps)
    ens = FQEEnsemble(fit, 1)
    ens.train(total, fit.cum[None], np.zeros(1, np.int64), [None], fit.rng, progress=progress,
              schedule=schedule)
    return ens.q()[0]


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
                 truncated: np.ndarray | None = None, cross=False) -> list:
    """The direct method for each of P policies on one log, with an interval that holds the
    fitted model's own error. Per policy: Q_hat (N, n) of the full fit, its estimate (the mean
    start value of the policy), and ``refits`` refits, each on the log's episodes resampled
    with replacement, started from the full fit's weights and trained ``refit_step_count``
    more steps on the resample (a warm-started bootstrap: a refit from scratch costs the full
    fit again, ``refits`` times). Each refit's replicate is its resample's mean start value.
    With refits, the estimate is the refits' mean start value over the whole log's episodes
    (bagged: one fit's value moves with its training noise, ~0.01 on icu-sepsis, and the mean
    of 10 refits less; chosen on the behaviour policy, whose FQE should equal the log's mean
    return: docs/notes/results-ope.md), the interval that +- :func:`student_quantile` x the replicates'
    standard deviation (a normal bootstrap interval, Student's t for the few replicates whose
    spread it estimates: 2.26 for 10 refits; their percentiles would be their extremes);
    without, the full fit's mean start value (``fit_estimate`` either way). The P fits train
    as one ensemble, then the P x ``refits`` refits as another
    (:class:`aoc_cli.ope.ensemble.FQEEnsemble`: each member one FQE, batched); every
    policy's fit starts from the same initialisation (``seed``) and
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

    ``truncated`` (E,): episodes cut short: the last step of one is censored, its target the
    value its next state is predicted to have (:mod:`aoc_cli.ope.ensemble`).

    ``cross``: each policy's record also holds "q_cross" (N, n), its Q_hat cross-fitted over
    two folds of the episodes (split at random, seeded by ``seed``): two more fits of each
    policy, one on each fold's episodes (every fit's steps, from the same initialisation, on
    mini-batches of their own generator: the other members' values do not change), each
    fold's rows given the Q_hat fitted on the other fold (WDR's control variate then never
    fits the episodes it corrects: :func:`aoc_cli.ope.value.policy_value`), and "folds" (E,)
    each episode's fold. True for every policy, or P bools: those policies only."""
    import time

    started = time.perf_counter()
    policies = [np.asarray(p, np.float64) for p in policies]
    P = len(policies)
    act = np.asarray(actions, np.int64).reshape(-1)
    logged = None
    if behaviour:                   # the logged actions as a policy (N, n): one-hot
        logged = np.zeros((len(act), policies[0].shape[1] if P else int(n_actions)))
        logged[np.arange(len(act)), act] = 1.0
    fit = FQEFit(observations, act, rewards, starts, policies[0] if P else logged, gamma, seed,
                 truncated=truncated)
    cums = np.stack([fit.cum] + [cumulative(p) for p in policies[1:]]) if P else None
    crossed = np.flatnonzero(np.broadcast_to(np.asarray(cross, bool), (P,))) \
        if len(fit.starts) > 2 else np.empty(0, np.int64)    # two folds need two episodes
    K = len(crossed)
    B0 = P + (logged is not None)                   # the fold members: 2K from here
    M = B0 + 2 * K
    total = default_steps(fit.n_rows, starts, gamma, fit.interval) \
        if steps is None else int(steps)
    k = refit_steps(total) if refit_step_count is None else int(refit_step_count)
    grand = M * total + (P * refits * k if refits > 1 else 0)
    n_episodes = len(fit.starts) - 1
    lengths = np.diff(fit.starts)
    folds = np.random.default_rng([seed, 2]).permutation(np.arange(n_episodes) % 2)
    row_fold = np.repeat(folds, lengths)                                    # (N,)
    fold_pools = [np.flatnonzero(row_fold == f) for f in (0, 1)]
    tick = (lambda base, m: None) if progress is None else \
        (lambda base, m: lambda done: progress(base + m * done, grand))
    behaviour_seed = [seed, 1]

    def fit_draw(keep, rng):        # members keep of [policies..., behaviour]: their draws
        draws = [] if not P else [sampler(fit, cums, np.arange(P), [None] * P, rng, P,
                                          keep=keep[keep < P])]
        if logged is not None and np.any(keep == P):
            draws.append(sampler(fit, cumulative(logged)[None], np.zeros(1, np.int64),
                                 [None], np.random.default_rng(behaviour_seed), 1))
        if np.any(keep >= B0):          # policy crossed[j] on fold f: member B0 + f * K + j
            draws.append(sampler(fit, cums, np.tile(crossed, 2),
                                 [fold_pools[0]] * K + [fold_pools[1]] * K,
                                 np.random.default_rng([seed, 3]), 2 * K,
                                 keep=keep[keep >= B0] - B0))
        return joined(*draws)

    ens = FQEEnsemble(fit, M)
    train_parts(ens, total, fit_draw, fit.rng, parts, progress=tick(0, M), schedule=schedule)
    first = fit.starts[:-1]
    q = ens.q()                                                             # (M, N, n)
    fitted = [float(np.mean((policies[i][first] * q[i][first]).sum(1))) for i in range(P)]
    out = [{"q": q[i], "estimate": fitted[i], "fit_estimate": fitted[i], "low": float("nan"),
            "high": float("nan"), "replicates": np.empty(0), "bagged": float("nan"),
            "steps": total, "refit_steps": 0} for i in range(P)]
    for j, i in enumerate(crossed):     # fold 0's rows from the fit on fold 1, and back
        out[i]["q_cross"] = np.where((row_fold == 0)[:, None], q[B0 + K + j], q[B0 + j])
        out[i]["folds"] = folds
    if refits > 1:
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
                                                       P * refits, keep=keep),
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
