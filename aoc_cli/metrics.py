"""Metrics of decisions scored against a log (``aoc evaluate``), with scikit-learn and scipy
(R^2, MAE and Spearman's rho in numpy, each checked against them in tests/test_metrics_fit.py:
importing sklearn.metrics and scipy.stats costs ~2.3 s of an ``aoc evaluate``).

Shapes: S scored steps; n actions (discrete); d_a action dims (continuous).

* imitation, discrete: accuracy, balanced accuracy, AUC (binary: the score of action 1;
  more actions: macro one-vs-rest), the majority rate, the confusion matrix (logged x decided)
  and calibration in 10 bins (binary: the score of action 1 against the observed rate of
  action 1; more actions: the top score against the accuracy);
* imitation, continuous: MAE and R^2 of the decided action (uniform average over dimensions);
* value: R^2, MAE and Spearman's rho of v_hat against the logged value target, and the
  agreement of the decision with the logged action (discrete) or its distance (continuous);
* both: residual quantiles against the corpus's typical residual, the share of decisions
  that extrapolate (residual over 3x typical), the share with a heterogeneity warning.
"""

from __future__ import annotations

import numpy as np

EXTRAPOLATION_FACTOR = 3.0
CALIBRATION_BINS = 10


def _f(x) -> float | None:
    return None if x is None or not np.isfinite(x) else float(x)


def calibration(scores: np.ndarray, y: np.ndarray, bins: int = CALIBRATION_BINS) -> list[dict]:
    """Binary: scores (S, 2) of the two actions, logged y (S,) -> per bin of the score of
    action 1: ``lo, hi, steps, predicted`` (mean score), ``observed`` (rate of action 1).
    More actions: bins of the top score, ``observed`` = the share decided right."""
    if scores.shape[1] == 2:
        p, hit = scores[:, 1], (y == 1).astype(float)
    else:
        p, hit = scores.max(1), (scores.argmax(1) == y).astype(float)
    edges = np.linspace(0.0, 1.0, bins + 1)
    which = np.clip(np.digitize(p, edges[1:-1], right=False), 0, bins - 1)
    out = []
    for b in range(bins):
        m = which == b
        out.append({"lo": float(edges[b]), "hi": float(edges[b + 1]), "steps": int(m.sum()),
                    "predicted": _f(p[m].mean()) if m.any() else None,
                    "observed": _f(hit[m].mean()) if m.any() else None})
    return out


def auc(y: np.ndarray, scores: np.ndarray) -> float | None:
    """ROC AUC of scores (S, n) for logged actions y (S,): binary on the score of action 1,
    else macro one-vs-rest; None when the held-out steps hold a single action."""
    from sklearn.metrics import roc_auc_score

    present = np.unique(y)
    if len(present) < 2:
        return None
    n = scores.shape[1]
    if n == 2:
        return float(roc_auc_score(y, scores[:, 1]))
    s = scores[:, present]
    s = s / np.maximum(s.sum(1, keepdims=True), 1e-12)
    s[s.sum(1) == 0] = 1.0 / len(present)
    if len(present) == 2:
        return float(roc_auc_score(y == present[1], s[:, 1]))
    return float(roc_auc_score(y, s, multi_class="ovr", average="macro", labels=present))


def classification(y: np.ndarray, decided: np.ndarray, scores: np.ndarray,
                   majority: int, full: bool = True) -> dict:
    """Discrete imitation metrics of decisions (S,) with scores (S, n) against logged y (S,);
    ``majority``: the corpus's most common action. ``full``: also confusion and calibration."""
    from sklearn.metrics import accuracy_score, balanced_accuracy_score, confusion_matrix

    out = {"accuracy": float(accuracy_score(y, decided)),
           "balanced_accuracy": float(balanced_accuracy_score(y, decided)),
           "auc": auc(y, scores),
           "majority_accuracy": float(np.mean(y == majority))}
    if full:
        n = scores.shape[1]
        out["confusion"] = confusion_matrix(y, decided, labels=np.arange(n)).tolist()
        out["calibration"] = calibration(scores, y)
    return out


def _r2(y: np.ndarray, pred: np.ndarray) -> float:
    """R^2 of pred against y, both (S, d), averaged uniformly over the d columns, as
    scikit-learn's ``r2_score`` (a constant column scores 1 if predicted exactly, else 0).
    Written here because importing sklearn.metrics costs ~1.4 s, more than the rest of
    ``aoc evaluate``'s summary (docs/notes/benchmarks-rounds.md, "The whole OPE, paired")."""
    ss_res = ((y - pred) ** 2).sum(0)
    ss_tot = ((y - y.mean(0)) ** 2).sum(0)
    ok = ss_tot != 0
    col = np.where(ss_res == 0, 1.0, 0.0)
    with np.errstate(over="ignore"):
        col[ok] = 1.0 - ss_res[ok] / ss_tot[ok]
    return float(col.mean())


def regression(y: np.ndarray, pred: np.ndarray) -> dict:
    """Continuous imitation: MAE and R^2 of decided actions (S, d_a) against logged (S, d_a)."""
    y, pred = np.asarray(y, float).reshape(len(y), -1), np.asarray(pred, float).reshape(len(y), -1)
    r2 = _r2(y, pred) if len(y) > 1 else None
    return {"mae": float(np.mean(np.abs(y - pred))), "r2": _f(r2),
            "mean_baseline_mae": float(np.mean(np.abs(y - y.mean(0))))}


def _ranks(x: np.ndarray) -> np.ndarray:
    """(S,) the ranks of x (S,), 1-based, ties given their mean rank (scipy's rankdata)."""
    _, inverse, counts = np.unique(x, return_inverse=True, return_counts=True)
    upper = np.cumsum(counts)                       # each distinct value's last rank
    return ((upper - (counts - 1) / 2.0)[inverse]).astype(np.float64)


def spearman(a: np.ndarray, b: np.ndarray) -> float:
    """Spearman's rho of a (S,) and b (S,): Pearson's r of their ranks, as scipy's spearmanr
    (written here: importing scipy.stats costs ~0.9 s of ``aoc evaluate``)."""
    ra, rb = _ranks(a), _ranks(b)
    ra, rb = ra - ra.mean(), rb - rb.mean()
    return float((ra @ rb) / np.sqrt((ra @ ra) * (rb @ rb)))


def value_fit(target: np.ndarray, v_hat: np.ndarray) -> dict:
    """v_hat (S,) against the logged value target (S,): R^2, MAE, Spearman's rho."""
    target, v_hat = np.asarray(target, float), np.asarray(v_hat, float)
    rho = spearman(target, v_hat) if len(target) > 2 and np.ptp(target) > 0 \
        and np.ptp(v_hat) > 0 else None
    return {"value_r2": _f(_r2(target[:, None], v_hat[:, None])) if len(target) > 1 else None,
            "value_mae": float(np.mean(np.abs(target - v_hat))),
            "value_spearman": _f(rho),
            "mean_baseline_mae": float(np.mean(np.abs(target - target.mean())))}


def agreement(logged: np.ndarray, decided: np.ndarray, discrete: bool) -> dict:
    """Discrete: the share of steps where the decision is the logged action; continuous:
    the mean Euclidean distance between them."""
    if discrete:
        return {"agreement": float(np.mean(np.asarray(logged) == np.asarray(decided))),
                "action_distance": None}
    d = np.linalg.norm(np.asarray(logged, float).reshape(len(logged), -1)
                       - np.asarray(decided, float).reshape(len(logged), -1), axis=1)
    return {"agreement": None, "action_distance": float(d.mean())}


def residual_summary(residual: np.ndarray, typical: float | None) -> dict:
    """Quantiles of the decisions' residuals (S,), and the same over the corpus's typical
    residual (its p50)."""
    q = {f"p{p}": float(np.quantile(residual, p / 100)) for p in (50, 90, 99)}
    q["mean"] = float(residual.mean())
    q["typical"] = _f(typical)
    if typical:
        q.update({f"{k}_over_typical": v / typical for k, v in list(q.items())
                  if k.startswith("p")})
    return q


def extrapolating_share(residual: np.ndarray, typical: float | None) -> float | None:
    """The share of steps whose residual is over 3x the corpus's typical residual."""
    if not typical:
        return None
    return float(np.mean(residual > EXTRAPOLATION_FACTOR * typical))
