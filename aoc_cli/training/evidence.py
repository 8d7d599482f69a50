"""Settings decided from the log's own evidence, never from a task's name.

``aoc train`` on any corpus, collected or ingested from a file, reads a few properties of the
log (:class:`Evidence`: discrete or continuous actions, rewards or none, the episodes' lengths
and how many reach the longest, how often an observation repeats, the number of episodes) and
decides, by the rules below (stated in docs/design.md, "Settings from the log's evidence"),
every training and controller setting the user left open. A flag the user gives wins;
``--paper`` takes the paper's value for all. Each rule's setting, its value and why go to the
output and to the model's config (``metrics.settings``); the controller's settings chosen are
saved with the model (``metrics.controller``) and every command that decides with it uses them
unless its own flag is given.

1. **mode**: value (AOC) when the log has rewards that vary; imitation (ABC) when it has none
   or every reward is the same (nothing to rank actions by).
2. **a finite state the log revisits** (value mode, discrete actions, an observation seen
   again at least :data:`REPEATS` of the rows): the belief reads no history (a state policy,
   ``history_length`` 0); each row's value is the behaviour's Q by fitted Q evaluation
   (``value`` fqe), bootstrapped through the revisits; undiscounted (``gamma`` 1) when the
   episodes end by themselves (rule 3 does not hold). The controller trusts an action only
   where the log took it in (nearly) that state (``residual_cap`` :data:`STATE_CAP` times the
   typical residual) and ranks each action by a lower bound of its value: the simultaneous
   :data:`STATE_LEVEL` one-sided bound over the step's K actions (Bonferroni: z_K =
   Phi^-1(1 - (1 - level) / K)), with the log's own noise of a value backed by one episode,
   measured once the row values exist (:func:`state_penalty`: ``support_penalty`` = z_K
   sigma_1 / sigma_v, in the controller's units).
3. **a horizon cut by a time limit** (value mode: at least :data:`AT_LIMIT` of the episodes
   have the longest length T: a limit ends them, not the task): ``gamma`` = 1 - 20 / T (an
   effective horizon 1 / (1 - gamma) of T / 20, so a row's return-to-go is not cut by the
   limit except in the last ~5% of an episode), between :data:`GAMMA_MIN` and the paper's 0.99.
4. **continuous actions, value mode**: the controller's ``epsilon`` keeps as many of the K
   uniform candidates as lie as near the corpus as the log's own actions do, measured on
   held-out episodes after training (:mod:`aoc_cli.training.epsilon_rule`; :func:`held_out`
   says where it runs).
5. **imitation of discrete actions on a small log**: the history length, width and weight
   decay by cross-validation over episodes: the lowest mean held-out log-loss among the
   candidates whose mean held-out ABC AUC is within 0.01 of the best
   (:mod:`aoc_cli.training.tuning`).
7. **do no harm** (value mode, discrete actions, no finite state: rule 2 cannot run): rule
   2 over the log's rows near the step in place of the state (every row within a radius
   of the step's denoised observation): each row valued by FQE over the
   neighbourhoods (``value`` neighbours, the belief's target too, ``history_length`` 0,
   undiscounted where episodes end by themselves), each action ranked by its lower bound over the
   rows near the step that took it, the clinicians' likely action kept unless another's
   bound beats its own (:mod:`aoc_cli.index.search.neighbourhood`); off where rule 2 runs.

>>> ev = Evidence(rows=10_000, episodes=50, discrete=False, n_actions=None, rewards=True,
...               length_median=200.0, length_max=200, at_limit=0.98, repeats=0.2)
>>> decide(ev, {"mode": None, "belief": None, "gamma": None})[0]
{'mode': 'value', 'gamma': 0.9}
"""

from __future__ import annotations

from dataclasses import asdict, dataclass
from statistics import NormalDist

import numpy as np

from aoc_cli.rows import distinct_rows

#: Rule 2: the share of rows whose observation occurs at another row above which the log's
#: states are taken as finite and revisited (icu-sepsis: 0.93; the continuous tasks <= 0.21).
REPEATS = 0.5
#: Rule 3: the share of episodes at the longest length above which a time limit cuts them
#: (pendulum: 0.98; tasks whose episodes end by themselves <= 0.2).
AT_LIMIT = 0.5
#: Rule 3: gamma's range.
GAMMA_MIN, GAMMA_MAX = 0.5, 0.99
#: Rule 3: the effective horizon is the time limit over this.
HORIZON_DIVISOR = 20
#: Rule 2's controller: the residual cap (times the typical p90), and the confidence of the
#: lower bound that ranks the actions (simultaneous over a step's K actions).
STATE_CAP, STATE_LEVEL = 0.01, 0.95

#: The training settings a rule may decide (BeliefConfig fields; None when not given).
TRAINING = ("mode", "belief", "gamma", "value", "dynamics_weight", "history_length")
#: The controller settings a rule may decide (ControllerConfig fields).
CONTROLLER = ("epsilon", "residual_cap", "support_penalty", "k", "do_no_harm")


@dataclass(frozen=True)
class Evidence:
    """What the rules read of a log. ``at_limit``: the share of episodes whose length is the
    longest; ``repeats``: the share of rows whose observation occurs at another row (1 -
    distinct observations / rows)."""

    rows: int
    episodes: int
    discrete: bool
    n_actions: int | None
    rewards: bool
    length_median: float
    length_max: int
    at_limit: float
    repeats: float

    @classmethod
    def of(cls, corpus) -> Evidence:
        """The evidence of a stored corpus (reads the observations, the rewards and the
        episode starts once)."""
        starts = np.asarray(corpus.episode_starts, dtype=np.int64)
        lengths = np.diff(starts)
        rewards = corpus.rewards
        varies = rewards is not None and len(rewards) > 0 and bool(np.ptp(rewards) > 0)
        obs = np.asarray(corpus.observations)
        distinct = len(distinct_rows(obs)[0])
        longest = int(lengths.max()) if len(lengths) else 0
        return cls(rows=int(corpus.n_rows), episodes=int(len(lengths)),
                   discrete=bool(corpus.discrete),
                   n_actions=int(corpus.action_space["n"]) if corpus.discrete else None,
                   rewards=varies,
                   length_median=float(np.median(lengths)) if len(lengths) else 0.0,
                   length_max=longest,
                   at_limit=float(np.mean(lengths == longest)) if len(lengths) else 0.0,
                   repeats=(len(obs) - distinct) / len(obs) if len(obs) else 0.0)

    def to_dict(self) -> dict:
        return asdict(self)

    @property
    def finite_states(self) -> bool:
        return self.discrete and self.repeats >= REPEATS

    @property
    def time_limit(self) -> bool:
        return self.at_limit >= AT_LIMIT and self.length_max > 1


def horizon_gamma(length: int) -> float:
    """Rule 3's discount for episodes cut at ``length`` steps."""
    return float(np.clip(1.0 - HORIZON_DIVISOR / max(length, 1), GAMMA_MIN, GAMMA_MAX))


def decide(ev: Evidence, given: dict) -> tuple[dict, list[dict]]:
    """The settings the rules decide among those ``given`` leaves open (None), training
    (:data:`TRAINING`) and controller (:data:`CONTROLLER`) together: (setting -> value, the
    reasons: one ``{"setting", "value", "why"}`` per setting decided). A rule whose premise
    depends on a setting the user gave (e.g. ``--mode``) follows the given value."""
    out, why = {}, []

    def take(name: str, value, reason: str) -> None:
        if given.get(name) is None and name not in out:
            out[name] = value
            why.append({"setting": name, "value": value, "why": reason})

    if ev.rewards:
        take("mode", "value", "the log has rewards that vary: AOC ranks actions by value")
    else:
        take("mode", "imitation", "the log has no rewards, or all equal: ABC imitates the "
                                  "behaviour")
    mode = given.get("mode") or out.get("mode")
    if mode != "value":
        return out, why
    value_belief = (given.get("belief") or "value") == "value" \
        and not given.get("dynamics_weight")
    if ev.finite_states and value_belief:
        seen = (f"an observation recurs at {ev.repeats:.0%} of the rows, with discrete "
                "actions: a finite state the log revisits")
        take("history_length", 0, seen + ": the belief reads no history (a state policy)")
        take("value", "fqe", seen + ": each row's value is the behaviour's Q by fitted Q "
                                    "evaluation, bootstrapped through the revisits")
        if not ev.time_limit:
            take("gamma", 1.0, "the episodes end by themselves (lengths from "
                               f"{ev.length_median:g} median to {ev.length_max}): undiscounted")
    if ev.finite_states:
        take("residual_cap", STATE_CAP, "a finite state the log revisits: an action is "
                                        "trusted only where the log took it in (nearly) that "
                                        "state")
    if ev.discrete and not ev.finite_states and value_belief:
        hood = (f"observations recur at {ev.repeats:.0%} of the rows, with discrete actions: "
                "no finite state, rule 7's neighbourhoods")
        take("value", "neighbours", hood + ": each row's value is the behaviour's Q by fitted "
                                           "Q evaluation over the log's rows near it (every row within "
                                           "a radius of its denoised observation)")
        take("history_length", 0, hood + ": the values are the observation's and the action's "
                                         "alone, and so is the belief")
        if not ev.time_limit:
            take("gamma", 1.0, "the episodes end by themselves (lengths from "
                               f"{ev.length_median:g} median to {ev.length_max}): undiscounted")
    if ev.discrete and ev.finite_states:
        take("do_no_harm", "off", "a finite state the log revisits: rule 2's exact-repeat "
                                  "bound ranks the actions and rule 6 chooses on held-out "
                                  "episodes")
    elif ev.discrete:
        take("do_no_harm", "on", f"observations recur at {ev.repeats:.0%} of the rows, too "
                                 "few for rule 2's exact repeats: each row is valued by FQE "
                                 "over the log's rows near it, each action ranked by its "
                                 "lower bound over the rows near the step that took it, and "
                                 "the clinicians' likely action is kept unless another's "
                                 "bound beats its own (rule 7)")
    if ev.time_limit and value_belief:
        take("gamma", horizon_gamma(ev.length_max),
             f"{ev.at_limit:.0%} of the episodes stop at {ev.length_max} steps (a time limit): "
             f"an effective horizon of a {HORIZON_DIVISOR}th of it")
    return out, why


def held_out(ev: Evidence, config) -> bool:
    """Whether rule 4 measures epsilon on held-out episodes for a model of ``config`` (a
    BeliefConfig): value mode, continuous actions, the value belief (the critic trains
    without the hook, and so does a corpus streamed from disk: the paper's epsilon)."""
    return config.mode == "value" and not ev.discrete and config.belief == "value"


#: The controller settings rule 2's selection chooses on held-out episodes
#: (:mod:`aoc_cli.training.controller_selection`); given any of them, it does not run.
SELECTED = ("residual_cap", "support_penalty")


def selects_controller(ev: Evidence, config, given: dict) -> bool:
    """Whether ``aoc train`` chooses the controller on the validation episodes for a model of
    ``config`` (a BeliefConfig): value mode with the value belief trained in memory, discrete
    actions, rewards, and none of :data:`SELECTED` nor ``do_no_harm`` ``given``: with a
    finite state the log revisits among rule 2's controllers, without one among rule 7's and
    the paper's."""
    return (config.mode == "value" and config.belief == "value" and ev.discrete
            and ev.rewards and not any(given.get(k) is not None
                                       for k in (*SELECTED, "do_no_harm")))


def penalises(ev: Evidence, config, given: dict) -> bool:
    """Whether rule 2 decides ``support_penalty`` (:func:`state_penalty`, once the row values
    of a model of ``config``, a BeliefConfig, exist): value mode, a finite state the log
    revisits, the penalty not ``given``."""
    return config.mode == "value" and ev.finite_states and given.get("support_penalty") is None


def one_step_noise(observations: np.ndarray, actions: np.ndarray, rewards: np.ndarray,
                   episode_starts: np.ndarray, values: np.ndarray, gamma: float,
                   censored: np.ndarray | None = None) -> tuple[float, int]:
    """(sigma_1, degrees of freedom): the sd of the value of a (state, action) backed by one
    episode, measured on the log. Each row's one-step target is y = r + gamma V(o'), V(o) the
    mean of the row ``values`` (N,) at observation o (fitted Q evaluation's own backup,
    :mod:`aoc_cli.belief.fqe`), y = r at an episode's last row; sigma_1 is the pooled sd of y
    within each (observation, action) the log repeats (the cut of a ``censored`` (E,) stay
    left out). A value backed by n episodes then has a standard error of about sigma_1 /
    sqrt(n). observations (N, d_o); actions (N,) int; episode_starts (E + 1,). (0, 0) when no
    pair repeats."""
    n = len(rewards)
    starts = np.asarray(episode_starts, np.int64)
    _, state = distinct_rows(np.asarray(observations).reshape(n, -1))
    values = np.asarray(values, np.float64)
    at_state = np.bincount(state, weights=values) / np.bincount(state)
    last = np.zeros(n, bool)
    last[starts[1:] - 1] = True
    nxt = np.minimum(np.arange(1, n + 1), n - 1)    # an episode's last row: masked below
    y = np.asarray(rewards, np.float64) + np.where(last, 0.0, gamma * at_state[state[nxt]])
    keep = np.ones(n, bool)
    if censored is not None:
        keep[(starts[1:] - 1)[np.asarray(censored, bool)]] = False
    _, pair = np.unique(state[keep] * (int(np.max(actions)) + 1)
                        + np.asarray(actions, np.int64).reshape(-1)[keep], return_inverse=True)
    count = np.bincount(pair)
    mean = np.bincount(pair, weights=y[keep]) / count
    dof = int((count - 1).sum())
    if dof == 0:
        return 0.0, 0
    return float(np.sqrt(np.sum((y[keep] - mean[pair]) ** 2) / dof)), dof


def lower_bound_z(n_actions: int, level: float = STATE_LEVEL) -> float:
    """z_K = Phi^-1(1 - (1 - level) / K): the one-sided normal quantile of a bound that holds
    for all K actions of a step at once (Bonferroni)."""
    return float(NormalDist().inv_cdf(1.0 - (1.0 - level) / max(int(n_actions), 1)))


def state_penalty(corpus, values: np.ndarray, gamma: float, censored=None
                  ) -> tuple[float | None, dict]:
    """Rule 2's ``support_penalty`` for a model of ``corpus`` whose row values are ``values``
    (N,): z_K sigma_1 / sigma_v (:func:`lower_bound_z`, :func:`one_step_noise`, sigma_v the
    std of the values, the unit of :func:`aoc_cli.control.support.penalised`), so the
    controller ranks each action by v_hat - z_K sigma_1 / sqrt(support); and its reason.
    None when the values do not vary or no (state, action) repeats."""
    noise, dof = one_step_noise(corpus.observations, corpus.actions, corpus.rewards,
                                corpus.episode_starts, values, gamma, censored)
    spread = float(np.std(values)) if len(values) else 0.0
    k = int(corpus.action_space["n"])
    z_k = lower_bound_z(k)
    if spread <= 0 or dof == 0:
        return None, {"setting": "support_penalty", "value": None,
                      "why": "a finite state the log revisits, but no (state, action) repeats "
                             "or the values do not vary: no noise to bound"}
    z = round(z_k * noise / spread, 3)
    return z, {"setting": "support_penalty", "value": z,
               "why": f"a finite state the log revisits: each action ranked by the "
                      f"simultaneous {STATE_LEVEL:.0%} lower bound of its value over the {k} "
                      f"actions (z {z_k:.3g}), with the log's noise of a value backed by one "
                      f"episode, sd {noise:.3g} ({dof:,} repeats of a state and action), "
                      f"{noise / spread:.3g} sd of the row values",
               "level": STATE_LEVEL, "z": z_k, "noise": noise, "dof": dof, "value_std": spread}


def summary(ev: Evidence) -> str:
    """The evidence in a few words, for ``aoc train``'s output."""
    actions = f"{ev.n_actions} discrete actions" if ev.discrete else "continuous actions"
    return (f"{ev.rows:,} rows, {ev.episodes:,} episodes of {ev.length_median:g} median and "
            f"{ev.length_max} most steps ({ev.at_limit:.0%} at the most), {actions}, "
            + ("rewards" if ev.rewards else "no rewards")
            + f", observations recurring at {ev.repeats:.0%} of the rows")


def describe(reasons: list[dict]) -> list[str]:
    """One line per setting decided, for ``aoc train``'s output."""
    return [f"{r['setting']} {r['value']:g}: {r['why']}" if isinstance(r["value"], float)
            else f"{r['setting']} {r['value']}: {r['why']}" for r in reasons]


def selection_lines(out: dict) -> list[str]:
    """What ``aoc train`` prints of the controller chosen on held-out episodes (the record of
    :func:`aoc_cli.training.controller_selection.select_controller`): one line per candidate,
    its FQE estimate and interval, the chosen one marked."""
    width = max(len(label(e["settings"])) for e in out["candidates"])
    def pairs(e: dict) -> str:
        if "pairs" not in e:
            return ""
        times = "time" if e["pairs"] == 1 else "times"
        return (f"; its median decision held out {e['pairs']:g} {times}, "
                f"{e.get('rare', 0.0):.0%} of its decisions fewer than "
                f"{out.get('min_pairs', 3)}"
                + (f": bound {e['bound']:.4f}" if e.get("valued", True) and "bound" in e
                   else f" ({e.get('not_valued', 'no estimate')})"))

    def fqe(e: dict) -> str:
        if e.get("screened"):
            return f"FQE not fitted, decided at {e['screened']:,} steps"
        if e.get("estimate") is None:
            return f"FQE not fitted, the logged action at {e['agrees']:.0%} of the steps"
        return (f"FQE {e['estimate']:.4f} [{e['low']:.4f}, {e['high']:.4f}], the logged "
                f"action at {e['agrees']:.0%} of the steps")

    return [f"{label(e['settings']):<{width}}  " + fqe(e)
            + pairs(e) + ("  <- chosen" if e["settings"] == out["chosen"] else "")
            for e in out["candidates"]]


def label(settings: dict) -> str:
    """``cap 0.01, penalty 5``; ``no cap, no penalty``; ``rule 7 (do no harm)``."""
    if "do_no_harm" in settings:
        return ("rule 7 (do no harm)" if settings["do_no_harm"] == "on"
                else "the paper's (no do no harm)")
    cap, pen = settings.get("residual_cap"), settings.get("support_penalty")
    return (("no cap" if cap is None else f"cap {cap:g}") + ", "
            + ("no penalty" if pen is None else f"penalty {pen:g}"))
