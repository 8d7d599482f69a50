"""What the log can support: the rule that withholds an estimate (docs/design.md, "Offline
policy evaluation: what is shown"), and the answer to "better than the logged behaviour?".

An importance-sampling estimate (PDWIS, WDR) is shown only when

1. the ESS of the whole-trajectory weights is at least :data:`MIN_ESS` (a weighted mean of
   ESS n has a standard error of about sd / sqrt(n): 0.41 / sqrt(500) = 0.018 for a survival
   outcome of 0.78, a mean error of 0.015; on icu-sepsis logs of 5,000 episodes AOC's ESS,
   25 to 256, gave PDWIS and WDR a mean |error| of 0.09: docs/notes/results-ope.md);
2. PDWIS only: the share of the policy's episodes whose end the log follows (``reached``) is
   at least :data:`MIN_REACHED` (PDWIS assumes the share it does not reach ends as the reached
   share does; WDR leaves that share to its Q model);
3. no more than :data:`MAX_UNDEFINED` of the bootstrap replicates are undefined (an interval
   over the defined ones alone is conditional on being defined);
4. the mean first-step ratio is within :data:`FIRST_STEP_TOLERANCE`, or 3 standard errors,
   of 1 (its expectation when the propensities are right: sum_a pi_e(a | s) = 1; a mean far
   from 1 says the propensities are not the behaviour's).

FQE needs no overlap and is kept when importance sampling is refused; it is shown only with
its refits (``fqe_refits`` >= 2): one fit's interval leaves the model's own error out and
covered the truth on 0 to 2 of 10 icu-sepsis logs (docs/notes/results-ope.md); and only where
its value of the logged behaviour (fitted beside the policies) lies within the 95% interval of
the log's mean return (:func:`fqe_refusal`): its interval does not hold its bias, and this is the
one policy whose value the log gives directly.

Whatever the estimator, an estimate or an interval end outside the range of the log's
(discounted) episode returns is never shown (:func:`outside_returns`): a policy's value is a
mean of returns, so a survival above 1 or a value below the worst episode is the estimator's
extrapolation, not anything the log vouches for. V(policy) - V(behaviour) is withheld with it.
"""

from __future__ import annotations

import math

#: Rule 1: the smallest ESS.
MIN_ESS = 500.0
#: Rule 2: PDWIS's smallest share of the policy's episodes whose end the log follows.
MIN_REACHED = 0.9
#: Rule 3: the largest share of undefined bootstrap replicates.
MAX_UNDEFINED = 0.05
#: Rule 4: how far the mean first-step ratio may be from 1 (or 3 standard errors, if more).
FIRST_STEP_TOLERANCE = 0.1
#: The estimator the verdict reads, the first of these that is shown.
VERDICT_ORDER = ("fqe", "wdr", "pdwis")


def min_ess(n_episodes: int) -> float:
    """The ESS rule 1 asks of a log of ``n_episodes`` (the same for any size: the error of a
    weighted mean depends on its ESS)."""
    return MIN_ESS


def refusal(name: str, diag: dict, n_episodes: int, undefined: float = 0.0,
            estimate: float = 0.0) -> str | None:
    """Why importance-sampling estimator ``name`` ("pdwis" or "wdr") is withheld on this log
    (None: shown). ``diag`` is :func:`aoc_cli.ope.estimators.diagnostics`'s; ``undefined``
    the estimate's share of undefined replicates; ``estimate`` its point (NaN: undefined)."""
    if not math.isfinite(estimate):
        return ("undefined: no logged episode follows the policy"
                if diag["first_step_weight"] == 0 else
                "undefined: no episode the policy reaches ends within the log")
    need = min_ess(n_episodes)
    if diag["ess"] < need:
        return f"ESS {diag['ess']:,.1f} of {n_episodes:,} (the rule asks {need:,.0f})"
    if name == "pdwis" and diag["reached"] < MIN_REACHED:
        return (f"the log follows {diag['reached']:.0%} of the policy's episodes to their end "
                f"(the rule asks {MIN_REACHED:.0%})")
    if undefined > MAX_UNDEFINED:
        return (f"{undefined:.0%} of the bootstrap replicates are undefined (the rule allows "
                f"{MAX_UNDEFINED:.0%})")
    off = abs(diag["first_step_weight"] - 1.0)
    se = diag.get("first_step_weight_se")
    allowed = max(FIRST_STEP_TOLERANCE, 3.0 * se if se is not None and math.isfinite(se) else 0)
    if off > allowed:
        return (f"mean first-step weight {diag['first_step_weight']:.3g}, not about 1 (the "
                "propensities do not look like the behaviour's)")
    return None


def fqe_refusal(behaviour_fqe: float, low: float, high: float) -> str | None:
    """Why FQE is withheld on this log (None: shown): its value of the logged behaviour
    ``behaviour_fqe`` outside [``low``, ``high``], the 95% interval of the log's mean return."""
    if low <= behaviour_fqe <= high:
        return None
    return (f"FQE off on the logged behaviour ({behaviour_fqe:.4g}, outside its mean "
            f"return's 95% interval [{low:.4g}, {high:.4g}]: a bias its interval does not "
            "hold)")


def outside_returns(entry: dict, low: float, high: float) -> str | None:
    """Why a shown estimate ``entry`` {estimate, low, high} is withheld for leaving
    [``low``, ``high``], the range of the log's episode returns (None: inside it; a
    float's rounding, a millionth of the range, is inside)."""
    if entry.get("estimate") is None:
        return None
    slack = 1e-6 * max(high - low, abs(high), abs(low), 1e-12)
    ends = [entry[k] for k in ("estimate", "low", "high") if entry.get(k) is not None]
    if all(math.isfinite(x) and low - slack <= x <= high + slack for x in ends):
        return None
    return (f"outside the range of the log's returns ({entry['estimate']:.4g} "
            f"[{entry['low']:.4g}, {entry['high']:.4g}] for returns in [{low:.4g}, "
            f"{high:.4g}]: the estimator's extrapolation)")


def withheld(reason: str) -> dict:
    """The JSON of an estimate the log does not support."""
    return {"estimate": None, "low": None, "high": None, "reason": reason}


def cell(entry: dict | None) -> str | None:
    """A table cell: "0.8123 [0.7900, 0.8301]" or "not estimable: ESS 4.6 of 3,000"."""
    if entry is None:
        return None
    if entry.get("estimate") is None:
        return "not estimable: " + str(entry.get("reason", "undefined")).split(" (")[0]
    return f"{entry['estimate']:.4f} [{entry['low']:.4f}, {entry['high']:.4f}]"


def verdict(improvement: dict) -> str:
    """One line: is the policy better than the logged behaviour? ``improvement`` estimator ->
    {estimate, low, high} of V(policy) - V(behaviour) (or withheld). Read from the first
    shown estimator of :data:`VERDICT_ORDER`: "shown" when its interval lies above 0 (or,
    worse, below it), else "not shown by this log". A negative estimate reads "worse than
    ... by" its magnitude, the interval turned round with it."""
    for name in VERDICT_ORDER:
        d = improvement.get(name)
        if d is None or d.get("estimate") is None:
            continue
        if d["estimate"] < 0:   # worse: said as such, the difference turned round
            word, e, lo, hi = "worse", -d["estimate"], -d["high"], -d["low"]
        else:
            word, e, lo, hi = "better", d["estimate"], d["low"], d["high"]
        shown = "shown" if lo > 0 else "not shown by this log"
        return (f"{word} than the logged behaviour by {e:.3f} [{lo:.3f}, {hi:.3f}] "
                f"({name.upper()}): {shown}")
    reasons = sorted({str(d.get("reason")).split(" (")[0] for d in improvement.values()
                      if d is not None and d.get("reason")})
    return ("better or worse than the logged behaviour: not estimable from this log"
            + (f" ({'; '.join(reasons)})" if reasons else ""))
