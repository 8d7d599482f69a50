"""Offline policy evaluation of decided policies on a held-out log (``aoc evaluate``'s value
mode): the estimators of :mod:`aoc_cli.ope.estimators` and :mod:`aoc_cli.ope.fqe`
applied to the controller's decisions (and each baseline's) at every logged step.

Inputs, for a log of E episodes and N steps (discrete actions, n of them): observations
(N, d_o), logged actions (N,), rewards (N,), ``starts`` (E + 1,), and per evaluated policy
its decisions (N,) (deterministic: pi_e(a | h_t) = 1 for the decided action) or its
probabilities (N, n). The behaviour's propensity of each logged action comes from a corpus
column when the log has one (``propensity``), else from a cross-fitted, calibrated model
of the log (:func:`aoc_cli.ope.propensity.fit_propensities`); the output says which, and
how well that model predicts held-out steps.

Output (JSON-ready), per policy: ``policy_value`` {estimator: {estimate, low, high}, or
{estimate: null, reason} where the log does not support it (:mod:`aoc_cli.ope.support`)},
``improvement`` {estimator: V(policy) - V(logged behaviour), its interval paired (the same
resamples for both)}, ``verdict`` (one line: better than the logged behaviour, shown or not),
``support`` (ESS, per-step ESS, the share reached, the mean first-step weight, the undefined
replicates); ``behaviour_value`` (the log's mean return, Kaplan-Meier's under censoring,
with its interval), ``ope`` (settings, the propensities' source and model, notes) and
``ope_warnings``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from aoc_cli.belief.targets import kept_values
from aoc_cli.errors import AocError, BadSetting, NoRewards, param
from aoc_cli.ope import estimators as ope
from aoc_cli.ope.fqe import (
    BATCH,
    HIDDEN,
    LEARNING_RATE,
    REFITS,
    SCHEDULE,
    TARGET_UPDATE,
    behaviour_fqe,
    default_steps,
)
from aoc_cli.index.search.neighbourhood import episodes_near, measured_cells
from aoc_cli.ope.parts import MAX_PARTS
from aoc_cli.ope.propensity import features, fit_propensities
from aoc_cli.ope.support import fqe_refusal
from aoc_cli.ope.value import _as_probs, fqe_values, policy_value
from aoc_cli.settings import Settings, setting
from aoc_cli.threads import one_thread

ESTIMATORS = ("pdwis", "wdr", "fqe")
#: The propensity column looked for when none is named.
PROPENSITY_COLUMN = "propensity"
#: An ESS below this share of the episodes (or below 30) is warned about.
ESS_WARN_SHARE = 0.01


@dataclass(frozen=True)
class OPESettings(Settings):
    """``estimators`` of :data:`ESTIMATORS`; ``gamma`` the discount of the value estimated
    (1: the mean undiscounted return of an episode); ``propensity`` a column name (None: the
    ``propensity`` column when the log has one, else an imitation model); ``fqe_steps``
    (None: :func:`aoc_cli.ope.fqe.default_steps`); ``fqe_refits`` the refits behind
    FQE's interval (:func:`aoc_cli.ope.fqe.bootstrap_fqe`; 0: one fit, its interval
    resamples the start values only and leaves the model's own error out); bootstrap
    replicates; seed; ``fqe_schedule`` FQE's learning rate, "cosine" (annealed to 0 over the
    fit and over each refit) or "constant"
    (:meth:`aoc_cli.ope.ensemble.FQEEnsemble.train`)."""

    label = "offline policy evaluation"

    estimators: tuple = setting(ESTIMATORS, param="ope",
                                help="Offline policy evaluation of the decisions (value mode): "
                                     "pdwis, wdr, fqe, comma-separated, or none.")
    gamma: float = setting(1.0, bounds="(0, 1]", param="ope_gamma",
                           help="Discount of the value the OPE estimates (1: the mean "
                                "undiscounted return of an episode).")
    propensity: str | None = setting(
        None, none=f"{PROPENSITY_COLUMN!r} when the log has it, else an imitation model "
                   "estimates them",
        help="Corpus column of the behaviour's probability of each logged action.")
    fqe_steps: int | None = setting(None, bounds=">= 1",
                                    none="about 30 passes over the log and 2.5 target syncs "
                                         "per step of its 99th-percentile episode length, "
                                         "1,500 to 12,000",
                                    help="Gradient steps of fitted Q evaluation.")
    fqe_refits: int = setting(REFITS, bounds=">= 0",
                              help="Refits on resampled episodes behind FQE's interval, each a "
                                   "fifth of the fit's steps (0: one fit, the interval then "
                                   "leaves the model's own error out).")
    n_boot: int = setting(ope.N_BOOTSTRAP, bounds=">= 1", help="Bootstrap replicates.")
    seed: int = setting(0, help="Seed of the bootstrap and FQE.")
    fqe_schedule: str = setting(SCHEDULE, choices=("cosine", "constant"),
                                help="FQE's learning rate: cosine (annealed to 0 over the fit "
                                     "and over each refit) or constant.")
    fqe_processes: int | None = setting(None, bounds=">= 1",
                                        none=f"the cores, at most {MAX_PARTS}",
                                        help="Processes FQE's fits train in (the same values "
                                             "in any number; 1 on a busy machine).")

    def check(self) -> OPESettings:
        super().check()
        bad = [name for name in self.estimators if name not in ESTIMATORS]
        if bad:
            raise BadSetting("ope", bad[0], f"unknown {param('ope')} estimator {bad[0]!r}: "
                             f"use {', '.join(ESTIMATORS)}")
        if self.fqe_refits == 1:
            raise BadSetting("fqe_refits", self.fqe_refits,
                             f"{param('fqe_refits')} must be 0 or at least 2, got "
                             f"{self.fqe_refits}")
        return self


def parse_estimators(text: str | None) -> tuple:
    """'pdwis,wdr,fqe' -> a tuple; 'none' -> ()."""
    if text is None:
        return ESTIMATORS
    names = [t.strip() for t in text.split(",") if t.strip()]
    if names == ["none"]:
        return ()
    bad = [n for n in names if n not in ESTIMATORS]
    if bad or not names:
        raise AocError(f"unknown OPE estimator {bad[0] if bad else text!r}: use "
                       f"{', '.join(ESTIMATORS)} (comma-separated) or none", param="ope")
    return tuple(dict.fromkeys(names))


def behaviour_propensities(data, logged: np.ndarray, settings: OPESettings,
                           history_length: int = 0):
    """((N,) the behaviour's probability of each logged action, source text, the estimated
    model's record (None for a column): held-out log-loss, calibration)."""
    columns = list(getattr(data, "manifest", {}).get("columns", []))
    name = settings.propensity
    if name is None and PROPENSITY_COLUMN in columns:
        name = PROPENSITY_COLUMN
    if name is not None:
        p = np.asarray(data.column(name), np.float64)
        return p, f"column {name!r} of {data.name!r}", None
    fit = fit_propensities(data.observations, logged, data.episode_starts, data.n_actions,
                           settings.seed, history_length)
    probs = fit.pop("probs")
    history = f" and the last {history_length} steps" if history_length else ""
    return (probs[np.arange(len(logged)), logged],
            "estimated: multinomial logistic regression of the logged action on the "
            f"observation{history}, cross-fitted over {fit['folds']} folds of "
            f"{data.name!r}'s episodes, temperature-calibrated", fit)


def fqe_record(settings: OPESettings, n_rows: int, starts: np.ndarray, gamma: float) -> dict:
    """What the behaviour's fitted Q evaluation (:func:`behaviour_targets`) is computed from:
    its estimator, settings and the libraries' versions (JSON)."""
    import torch

    return {"value": "fqe", "gamma": float(gamma),
            "estimator": "fitted Q evaluation of the logged behaviour (SARSA), plain torch",
            "steps": int(settings.fqe_steps or default_steps(n_rows, starts, gamma)),
            "batch": BATCH, "learning_rate": LEARNING_RATE, "target_update": TARGET_UPDATE,
            "hidden": list(HIDDEN), "schedule": settings.fqe_schedule,
            "seed": int(settings.seed), "truncated": "censored, bootstrapped",
            "torch": torch.__version__}


def behaviour_targets(data, gamma: float, seed: int = 0,
                      block: dict | None = None) -> np.ndarray | None:
    """(N,) the logged behaviour's Q_hat(o_t, a_t) of every step of held-out log ``data`` by
    fitted Q evaluation at FQE's default settings (discount ``gamma``, ``seed``):
    ``aoc evaluate``'s held-out value target of a model whose values are ``fqe`` (an estimate
    of the same Q(o, a), by another estimator, from the held-out log alone). The OPE's own
    (``block``, an :func:`ope_block`) when it fitted the behaviour at those settings; else
    fitted alone (:func:`aoc_cli.ope.fqe.behaviour_fqe`, the same values): a quicker
    OPE does not change the target. Kept beside the log
    (:func:`aoc_cli.belief.targets.kept_values`). None where it cannot run (continuous
    actions, no rewards): the caller then uses aoc's own fitted Q evaluation."""
    if not data.discrete or not data.has_rewards:
        return None
    settings = OPESettings(seed=seed)
    record = fqe_record(settings, data.n_rows, data.episode_starts, gamma)
    fresh = None if block is None else block.get("behaviour_fqe")
    if fresh is not None:
        ran = block["settings"]
        if fqe_record(ran, data.n_rows, data.episode_starts, ran.gamma) != record \
                or block.get("history_length", 0):
            fresh = None                # the OPE's FQE ran at other settings or inputs

    def compute():
        if fresh is not None:
            return fresh["logged"]
        with one_thread():
            return behaviour_fqe(data.observations, np.asarray(data.actions, np.int64),
                                 data.rewards, data.episode_starts, data.n_actions, gamma,
                                 record["steps"], settings.seed,
                                 schedule=settings.fqe_schedule,
                                 truncated=truncated(data))["logged"]

    return kept_values(data, "fqe-behaviour", record, compute)


def warnings_for(name: str, rec: dict, n_episodes: int) -> list[str]:
    """A small ESS beside an importance-sampling estimate that is still shown (where the rule
    withholds them, their cells already say "not estimable: ESS ..."); a pair of estimators
    whose intervals do not overlap."""
    out = []
    small = max(30.0, ESS_WARN_SHARE * n_episodes)
    shown = [k for k in ("pdwis", "wdr")
             if (rec["policy_value"].get(k) or {}).get("estimate") is not None]
    if rec["ess"] < small and shown:
        out.append(f"policy {name!r}: effective sample size {rec['ess']:.1f} of {n_episodes} episodes "
                   "(few logged episodes follow this policy; its estimates are unreliable)")
    items = [(k, e) for k, e in rec["policy_value"].items() if e.get("estimate") is not None]
    for i, (a, ea) in enumerate(items):
        for b, eb in items[i + 1:]:
            if ea["high"] < eb["low"] or eb["high"] < ea["low"]:
                out.append(f"policy {name!r}: {a} ({ea['estimate']:.4g}) and {b} ({eb['estimate']:.4g}) "
                           "disagree (their 95% intervals do not overlap)")
    return out


def check_log(data) -> None:
    """Refuse a held-out log the OPE cannot use: continuous actions or no rewards."""
    if not data.discrete:
        raise BadSetting("ope", None, "offline policy evaluation needs discrete actions (a "
                         "deterministic policy of continuous actions matches no logged action); "
                         f"use {param('ope', 'none')}")
    if not data.has_rewards:
        raise NoRewards(data.name, "offline policy evaluation",
                        f"corpus {data.name!r} has no rewards: offline policy evaluation needs "
                        f"the logged rewards; use {param('ope', 'none')}", param="ope")


def off_policy_values(data, logged: np.ndarray, policies: dict, settings: OPESettings,
                      progress=None, history_length: int = 0) -> dict:
    """The OPE block of ``aoc evaluate`` for held-out corpus ``data`` (every row, in order):
    ``policies`` name -> decisions (N,) or probabilities (N, n). Returns {"ope": ...,
    "behaviour_value": ... (with "fqe", the direct method's value of the logged behaviour,
    when FQE ran: a check of FQE against the log's mean return), "policies": {name:
    {policy_value, ess, notes}}, "ope_warnings"} and, when FQE ran, "behaviour_fqe" (the
    behaviour's record of :func:`aoc_cli.ope.fqe.fqe_policies`). ``history_length``: the
    steps of history the policies decide from (the propensity model's too). Truncated
    episodes are censored (:mod:`aoc_cli.ope.estimators`)."""
    check_log(data)
    logged = np.asarray(logged, np.int64)
    if len(logged) != data.n_rows:
        raise AocError(f"{len(logged)} decided steps for a log of {data.n_rows} rows")
    log = ope.Log(data.episode_starts, data.rewards, settings.gamma, truncated(data))
    propensity, source, model = behaviour_propensities(data, logged, settings, history_length)
    ope.ratios(np.ones(len(logged)), propensity)       # refuses a zero propensity up front
    # the behaviour's own value: the mean return, or under censoring Kaplan-Meier's
    mean = ope.bootstrap(log, {"mean": ope.behaviour(log)}, n_boot=settings.n_boot,
                         seed=settings.seed)["mean"]
    out = {"ope": {"estimators": list(settings.estimators), "gamma": settings.gamma,
                   "propensity": source, "propensity_model": model,
                   "truncated_episodes": int(log.truncated.sum()),
                   "bootstrap": settings.n_boot,
                   "fqe_steps": (settings.fqe_steps or default_steps(
                       data.n_rows, data.episode_starts, settings.gamma))
                   if "fqe" in settings.estimators or "wdr" in settings.estimators else None,
                   "fqe_refits": settings.fqe_refits if "fqe" in settings.estimators
                   else None},
           "behaviour_value": mean.as_dict(), "policies": {}, "ope_warnings": []}
    probs = {name: _as_probs(p, data.n_actions) for name, p in policies.items()}
    # FQE's Q from what the policies decide from: the observation and, with a history, the
    # last history_length observations and actions (the propensity model's features)
    inputs = features(data.observations, logged, data.episode_starts, data.n_actions,
                      history_length)
    out["ope"]["fqe_inputs"] = "the observation" + (
        f" and the last {history_length} steps" if history_length else "")
    fqes = fqe_values(log, inputs, logged, list(probs.values()), settings, progress,
                      behaviour=True, propensity=propensity)
    if len(fqes) > len(probs):          # the logged behaviour's, last
        own = fqes.pop()
        out["behaviour_fqe"] = own
        out["behaviour_value"]["fqe"] = own["estimate"]
        low, high = out["behaviour_value"]["low"], out["behaviour_value"]["high"]
        off = fqe_refusal(own["estimate"], low, high)
        if off is not None:
            out["ope_warnings"].append(
                f"fqe values the logged behaviour at {own['estimate']:.4g}, outside the 95% "
                f"interval of its mean return ({low:.4g} to {high:.4g}): the direct method "
                "is off on this log, and so may be its values of the policies (withheld)")
            for rec in fqes:
                if rec is not None:
                    rec["withheld"] = off
    held = None
    if "fqe" in settings.estimators and any(f is not None for f in fqes):
        held = episodes_near(data.observations, logged, data.episode_starts,
                             data.n_actions, measured_cells(data))        # (N, n)
    for i, ((name, policy), fqe) in enumerate(zip(probs.items(), fqes)):
        try:
            rec = policy_value(log, inputs, logged, propensity, policy,
                               data.n_actions, settings, progress, fqe=fqe, held=held)
        except AocError as err:
            if i == 0:          # the first policy is the one asked about: its error is the run's
                raise AocError(f"policy {name!r}: {err.marked}") from None
            out["policies"][name] = {"policy_value": None, "ess": None, "notes": [str(err)]}
            continue
        out["policies"][name] = rec
        out["ope_warnings"] += warnings_for(name, rec, log.n_episodes)
    return out


def truncated(data) -> np.ndarray:
    """(E,) whether each episode of ``data`` (a stored corpus or its arrays) was cut short (its
    last row a truncation, not a terminal): censored by the estimators."""
    last = np.asarray(data.episode_starts, np.int64)[1:] - 1
    trunc, term = _flags(data, "truncations"), _flags(data, "terminals")
    if trunc is None:
        return np.zeros(len(last), bool)
    out = np.asarray(trunc, bool)[last]
    return out & ~np.asarray(term, bool)[last] if term is not None else out


def _flags(data, name: str) -> np.ndarray | None:
    """A stored corpus's column ``name`` (read), or the attribute of in-memory arrays."""
    if hasattr(data, "read"):
        try:
            return data.read(name)
        except AocError:
            return None
    return getattr(data, name, None)


def wanted(settings: OPESettings | None, mode: str, data) -> bool:
    """Whether ``aoc evaluate`` runs the OPE: asked for (estimators given) in value mode.
    ``settings`` None is the default: the OPE when the log allows it (value mode, discrete
    actions, rewards); explicit settings on a log that does not allow it are refused by
    :func:`check_log` before anything is decided."""
    if settings is None:
        return mode == "value" and data.discrete and data.has_rewards
    if not settings.estimators:
        return False
    if mode != "value":
        raise BadSetting("ope", None, "offline policy evaluation is for value-mode models (an "
                         "imitation model has no values to compare); use "
                         f"{param('ope', 'none')}")
    check_log(data)         # before any step is decided
    columns = list(getattr(data, "manifest", {}).get("columns", []))
    if settings.propensity is not None and settings.propensity not in columns:
        raise BadSetting("propensity", settings.propensity,
                         f"corpus {data.name!r} has no column {settings.propensity!r} for the "
                         f"behaviour's propensities ({param('propensity')}; columns: "
                         f"{', '.join(columns) or 'none'})")
    return True


def ope_block(mode: str, data, res, settings: OPESettings | None, seed: int = 0,
              progress=None, history_length: int = 0) -> dict | None:
    """The OPE of the controller's decisions (``res.decided``) and of each baseline's on
    held-out log ``data`` (:func:`off_policy_values`, with the settings used under
    "settings"), when :func:`wanted` (``seed``: of the default settings); else None."""
    if not wanted(settings, mode, data):
        return None
    settings = settings or OPESettings(seed=seed)
    if not np.array_equal(res.row, np.arange(data.n_rows)):
        raise AocError("offline policy evaluation needs every step of the held-out log")
    policies = {"aoc": res.decided}
    for name, b in res.baselines.items():
        if b.get("decided") is not None:
            policies[name] = b["decided"]
    block = off_policy_values(data, res.logged, policies, settings, progress, history_length)
    block["settings"] = settings
    block["history_length"] = history_length
    return block


def put_ope(summary: dict, block: dict | None) -> None:
    """Put an :func:`ope_block` into an ``aoc evaluate`` summary (nothing for None)."""
    if block is None:
        return
    own = block["policies"]["aoc"]
    keys = ("policy_value", "improvement", "verdict", "ess", "support")
    summary.update({k: own.get(k) for k in keys})
    summary["behaviour_value"] = block["behaviour_value"]
    summary["ope"] = {**block["ope"], "notes": own["notes"]}
    for name, rec in block["policies"].items():
        if name != "aoc":
            summary["baselines"][name].update({k: rec.get(k) for k in keys},
                                              ope_notes=rec["notes"])
    summary["ope_warnings"] = block["ope_warnings"]
