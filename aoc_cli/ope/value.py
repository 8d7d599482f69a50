"""One policy's offline evaluation on a log (:func:`policy_value`): PDWIS and WDR with their
bootstrap intervals, FQE with its refits' (:func:`fqe_values`), each shown where the log
supports it (:mod:`aoc_cli.ope.support`), V(policy) - V(logged behaviour) by each with a
paired interval, and the verdict line. ``settings`` is an
:class:`aoc_cli.ope.evaluate_block.OPESettings` (its estimators, gamma, bootstrap, seed and FQE
settings)."""

from __future__ import annotations

import numpy as np

from aoc_cli.ope import estimators as ope
from aoc_cli.ope.fqe import fqe_policies, student_quantile
from aoc_cli.ope.support import min_ess, outside_returns, refusal, verdict, withheld


def _as_probs(policy: np.ndarray, n_actions: int) -> np.ndarray:
    policy = np.asarray(policy)
    if policy.ndim == 1:
        return np.eye(n_actions)[policy.astype(np.int64)]
    return np.asarray(policy, np.float64)


def policy_value(log: ope.Log, observations, logged, propensity, policy, n_actions: int,
                 settings, progress=None, fqe: dict | None | str = "fit",
                 held: np.ndarray | None = None) -> dict:
    """One policy's ``policy_value`` {estimator: Estimate dict, or withheld}, ``improvement``
    (over the logged behaviour, paired), ``verdict``, ``ess``, ``support`` and notes.
    ``policy`` (N,) decisions or (N, n) probabilities at the logged steps; ``fqe`` its direct
    method (one entry of :func:`fqe_values`, computed with the other policies'; "fit": fitted
    here for this policy alone). ``held`` (N, n): the log's episodes near each step that took
    each action (:class:`aoc_cli.index.search.neighbourhood.Neighbourhood`): FQE's interval is
    widened by the share of the policy's decisions the log hardly holds
    (:func:`hardly_held`)."""
    probs = _as_probs(policy, n_actions)                          # (N, n)
    rows = np.arange(len(logged))
    rho = ope.ratios(probs[rows, logged], propensity)
    diag = ope.diagnostics(log, rho)
    out: dict = {"ess": diag["ess"], "notes": []}
    returns = log.returns()
    # paired: every estimator's same draws; the behaviour's value Kaplan-Meier's under
    # censoring (a cut stay is not a return of 0: the difference would gain its share)
    specs: dict = {"behaviour": ope.behaviour(log)}
    if "pdwis" in settings.estimators:
        specs["pdwis"] = ("pdwis", rho)
    if isinstance(fqe, str):
        fqe = fqe_values(log, observations, logged, [probs], settings, progress,
                         propensity=propensity)[0]
    q = None if fqe is None else fqe["q"]                                     # (N, n)
    if fqe is not None and fqe.get("note"):
        out["notes"].append(fqe["note"])
    refitted = q is not None and len(fqe["replicates"]) > 1
    if "wdr" in settings.estimators and q is not None:
        qw = fqe.get("q_cross", q)          # cross-fitted: no episode corrects by its own fit
        specs["wdr"] = ("wdr", rho, qw[rows, logged], (probs * qw).sum(1))
    est = ope.bootstrap(log, specs, n_boot=settings.n_boot, seed=settings.seed)
    mean = est.pop("behaviour")
    value, gain = {}, {}
    for name in ("pdwis", "wdr"):
        if name not in settings.estimators:
            continue
        if name not in est:
            value[name] = gain[name] = withheld("no Q model (" + (fqe or {}).get(
                "note", "fqe did not run") + ")")
            continue
        e = est[name]
        why = refusal(name, diag, log.n_episodes, e.undefined, e.estimate)
        value[name] = withheld(why) if why else e.as_dict()
        gain[name] = withheld(why) if why else e.minus(mean).as_dict()
    if "fqe" in settings.estimators and q is not None:
        if refitted:
            value["fqe"] = {k: fqe[k] for k in ("estimate", "low", "high")}
            gain["fqe"] = _fqe_gain(fqe, log)
            b, k, n = len(fqe["replicates"]), fqe["refit_steps"], fqe["steps"]
            out["notes"].append(
                f"fqe: the estimate is the mean of {b} refits' start values (bagged; one "
                f"fit's: {fqe['fit_estimate']:.4g}), the interval +- "
                f"{student_quantile(b - 1):.3g} sd of the refits' estimates (Student's t, "
                f"{b - 1} degrees of freedom), each refit on the log's episodes resampled "
                f"with replacement, {k:,} steps on from the full fit's {n:,}-step weights "
                f"(the refits' sampling and training error is in it; cost "
                f"{(n + b * k) / n:.1f}x one fit)")
        else:
            why = ("one fit (fqe_refits 0): its interval would leave the model's own error "
                   f"out; its start values give {fqe['fit_estimate']:.4g}")
            value["fqe"] = gain["fqe"] = withheld(why)
    if value.get("fqe", {}).get("estimate") is not None and fqe.get("withheld"):
        # FQE off on the logged behaviour (support.fqe_refusal)
        value["fqe"] = gain["fqe"] = withheld(fqe["withheld"])
    lo, hi = float(returns.min()), float(returns.max())
    if held is not None:
        share = hardly_held(probs, held)
        out["support"] = {"hardly_held": share}
        if value.get("fqe", {}).get("estimate") is not None and share > 0:
            why = widen(value["fqe"], gain["fqe"], share, lo, hi)
            if why is not None:
                value["fqe"] = gain["fqe"] = withheld(why)
            else:
                out["notes"].append(
                    f"fqe: the log hardly holds {share:.1%} of the policy's decisions (fewer "
                    f"than {HELD_EPISODES} of its episodes near the step took that action): "
                    f"the interval is widened by that share of the returns' range, "
                    f"+- {share * (hi - lo):.3g}")
    for name, entry in value.items():       # never a value the returns cannot take
        why = outside_returns(entry, lo, hi)
        if why is None and gain.get(name, {}).get("estimate") is not None:
            why = outside_returns(gain[name], lo - hi, hi - lo)
        if why is not None:
            value[name] = gain[name] = withheld(why)
    out["policy_value"] = value
    out["improvement"] = gain
    out["verdict"] = verdict(gain)
    out["support"] = {**out.get("support", {}), "ess": diag["ess"],
                      "ess_per_step": [round(x, 2) for x in diag["ess_per_step"]],
                      "reached": diag["reached"], "first_step_weight": diag["first_step_weight"],
                      "undefined_replicates": {k: e.undefined for k, e in est.items()}}
    return out


#: A decision is hardly held when fewer than this many of the log's episodes near its step
#: took its action (rule 6's "held out fewer than 3 times", in its continuous form).
HELD_EPISODES = 3


def hardly_held(probs: np.ndarray, held: np.ndarray) -> float:
    """The share of a policy's decisions (probabilities (N, n) at the N logged steps) whose
    action fewer than :data:`HELD_EPISODES` of the log's episodes near the step took
    (``held`` (N, n))."""
    thin = np.asarray(held)[:, :probs.shape[1]] < HELD_EPISODES
    return float(np.mean((probs * thin).sum(1))) if len(probs) else 0.0


def widen(value: dict, gain: dict, share: float, lo: float, hi: float) -> str | None:
    """FQE's value and difference intervals widened, in place, by ``share`` x the returns'
    range [``lo``, ``hi``] each way (on the decisions the log hardly holds FQE's Q is
    extrapolation: worth anything from the worst return to the best); the reason to withhold
    them when the widened value leaves that range (None: shown, widened)."""
    pad = share * (hi - lo)
    low, high = value["low"] - pad, value["high"] + pad
    if low < lo - 1e-9 * max(hi - lo, 1e-12) or high > hi + 1e-9 * max(hi - lo, 1e-12):
        return (f"the log hardly holds {share:.0%} of the policy's decisions (fewer than "
                f"{HELD_EPISODES} of its episodes near the step took that action): FQE's "
                f"value there is extrapolation, its interval widened by that share of the "
                f"returns' range ({value['estimate']:.4g} [{low:.4g}, {high:.4g}]) leaves "
                f"[{lo:.4g}, {hi:.4g}]")
    value["low"], value["high"] = low, high
    gain["low"], gain["high"] = gain["low"] - pad, gain["high"] + pad
    return None


def _fqe_gain(fqe: dict, log: ope.Log) -> dict:
    """V(policy) - V(behaviour) by FQE: each refit's estimate less the behaviour's own value
    (:func:`aoc_cli.ope.estimators.behaviour`: the mean return, Kaplan-Meier's under
    censoring) over the same resampled episodes (the refit's ``counts``), +- Student's t sd
    of those paired differences, around the bagged estimate less the behaviour's value."""
    counts = np.asarray(fqe["counts"], np.float64)                    # (refits, E)
    diffs = np.asarray(fqe["replicates"]) - ope.behaviour_values(log, counts)
    point = fqe["estimate"] - float(ope.behaviour_values(log, np.ones((1, log.n_episodes)))[0])
    half = student_quantile(len(diffs) - 1) * float(np.std(diffs, ddof=1))
    return {"estimate": point, "low": point - half, "high": point + half}


def fqe_values(log: ope.Log, observations, logged, policies: list, settings,
               progress=None, behaviour: bool = False, propensity=None) -> list:
    """The direct method for each policy (N, n) at once
    (:func:`aoc_cli.ope.fqe.fqe_policies`: one batched ensemble), when an estimator needs it: with refits when FQE is asked for and
    ``settings.fqe_refits`` > 1, and cross-fitted over two folds of episodes when WDR is
    asked for (its ``q_cross``): with ``propensity`` (N,), only for the policies whose ESS
    meets :data:`aoc_cli.ope.support.MIN_ESS` (below it the rule withholds WDR whatever its Q,
    and its fold fits would cost ~1.5x the FQE); a list of propensities: where any does. Each entry None (no estimator needs a Q
    model) or a record.
    ``behaviour``:
    the logged behaviour's record last (``fqe_policies``'s), when FQE runs."""
    if "fqe" not in settings.estimators and "wdr" not in settings.estimators:
        return [None] * len(policies)
    refits = settings.fqe_refits if "fqe" in settings.estimators else 0
    return fqe_policies(observations, logged, log.rewards, log.starts, policies,
                        settings.gamma, settings.fqe_steps, refits if refits > 1 else 0,
                        seed=settings.seed, progress=progress, schedule=settings.fqe_schedule,
                        behaviour=behaviour, parts=settings.fqe_processes,
                        truncated=log.truncated, cross=_crossed(log, logged, policies,
                                                                propensity, settings))


def _crossed(log: ope.Log, logged, policies: list, propensity, settings) -> list:
    """Which policies' Q :func:`fqe_values` cross-fits for WDR (its docstring)."""
    if "wdr" not in settings.estimators:
        return [False] * len(policies)
    if propensity is None:
        return [True] * len(policies)
    rows = np.arange(len(logged))       # the policies' (N, n) probabilities
    props = propensity if isinstance(propensity, (list, tuple)) else [propensity]
    return [any(ope.ess(log, ope.ratios(np.asarray(p)[rows, logged], prop))
                >= min_ess(log.n_episodes) for prop in props) for p in policies]
