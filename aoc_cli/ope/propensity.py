"""The behaviour policy estimated from a log that has no propensity column: a multinomial
logistic regression of the logged action on the observation (and, when the evaluated policy
uses the history, on the previous ``history_length`` observations and actions), cross-fitted
over the log's episodes and calibrated.

- **Cross-fitted**: the episodes split into :data:`FOLDS` folds at random; each step's
  probabilities come from the model fitted to the other folds, so no step's propensity is
  fitted to its own action (an in-sample fit is over-confident on the logged action, which
  shrinks the weights of the episodes that follow a policy).
- **No default pull to uniform**: scikit-learn's default L2 penalty (C = 1) shrinks the logits
  toward equal probabilities whatever the log; here the penalty is the one of
  :data:`INVERSE_PENALTIES` with the smallest out-of-fold log-loss (on 45,000 icu-sepsis steps
  C = 1 and C = 10^4 gave 1.477 and 1.479; on 5,400, unpenalised, 1.73 against the true
  propensities' 1.43: a small log needs the penalty, a large one hardly feels it).
- **Calibrated**: one temperature T divides the out-of-fold logits, chosen to minimise their
  log-loss (Guo et al. 2017, temperature scaling; ~1.03 on icu-sepsis).
- **No floor**: a softmax is never 0; the old 1e-3 floor changed every small propensity.

Reported (``aoc evaluate``'s ``ope.propensity_model``): the held-out (out-of-fold) log-loss of
the logged actions, that of the log's action frequencies for scale, the temperature, and the
calibration: the expected calibration error over every (step, action) pair in 10 bins of
predicted probability, with the bins.
"""

from __future__ import annotations

import warnings

import numpy as np

#: Folds of the cross-fit (episodes), the inverse L2 penalties tried (strongest first), the
#: calibration's bins.
FOLDS = 3
INVERSE_PENALTIES = (0.1, 1.0, 10.0, 100.0)
BINS = 10


def features(observations, actions, starts, n_actions: int, history_length: int = 0
             ) -> np.ndarray:
    """(N, d) the observation, then for k = 1..``history_length`` the observation and one-hot
    action k steps back in the same episode (zeros before its start)."""
    x = np.asarray(observations, np.float64).reshape(len(actions), -1)
    if history_length <= 0:
        return x
    starts = np.asarray(starts, np.int64)
    act = np.asarray(actions, np.int64)
    step = np.arange(len(act)) - np.repeat(starts[:-1], np.diff(starts))
    parts = [x]
    for k in range(1, int(history_length) + 1):
        ok = (step >= k)[:, None]
        src = np.maximum(np.arange(len(act)) - k, 0)
        parts += [np.where(ok, x[src], 0.0), np.where(ok, np.eye(n_actions)[act[src]], 0.0)]
    return np.concatenate(parts, axis=1)


def fit_propensities(observations, actions, starts, n_actions: int, seed: int = 0,
                     history_length: int = 0, folds: int = FOLDS) -> dict:
    """{"probs" (N, n) the cross-fitted, calibrated behaviour probabilities, "log_loss",
    "log_loss_frequencies", "temperature", "ece", "calibration" (bins), "folds",
    "inverse_penalty" (the C chosen)} (module docstring)."""
    # scikit-learn and scipy only here (~1 s to import; the column path never needs them)
    from scipy.optimize import minimize_scalar
    from sklearn.linear_model import LogisticRegression
    from sklearn.preprocessing import StandardScaler

    y = np.asarray(actions, np.int64)
    starts = np.asarray(starts, np.int64)
    x = features(observations, y, starts, n_actions, history_length)
    n_episodes = len(starts) - 1
    k = max(2, min(int(folds), n_episodes))
    fold = np.random.default_rng(seed).permutation(np.arange(n_episodes) % k)
    fold = np.repeat(fold, np.diff(starts))                               # (N,)
    rows = np.arange(len(y))
    every = {c: np.full((len(y), n_actions), -np.inf) for c in INVERSE_PENALTIES}
    for f in range(k):
        train, test = fold != f, fold == f
        present = np.unique(y[train])
        if len(present) == 1:                        # one action in the other folds
            for logits in every.values():
                logits[np.ix_(test, present)] = np.log(train.sum())
                logits[test] = np.where(np.isfinite(logits[test]), logits[test], 0.0)
            continue
        scale = StandardScaler().fit(x[train])
        xt, xs = scale.transform(x[train]), scale.transform(x[test])
        model = LogisticRegression(max_iter=300, random_state=seed, warm_start=True)
        for c in INVERSE_PENALTIES:                  # warm-started along the path
            with warnings.catch_warnings():          # lbfgs's iteration cap: a fit still
                warnings.simplefilter("ignore")      # judged by its held-out log-loss
                model.set_params(C=c).fit(xt, y[train])
            z = model.decision_function(xs)
            if z.ndim == 1:                          # two classes: one logit
                z = np.stack([np.zeros_like(z), z], axis=1)
            every[c][np.ix_(test, model.classes_)] = z
        for logits in every.values():    # an action the other folds never took: about 1 in
            part = logits[test]          # their steps, not 0 (a logged action had p > 0)
            low = np.where(np.isfinite(part), part, np.inf).min(1, keepdims=True)
            logits[test] = np.where(np.isfinite(part), part, low - np.log(train.sum()))

    def held_out(logits):
        z = logits - logits.max(1, keepdims=True)
        lp = z[rows, y] - np.log(np.exp(z).sum(1))
        return float(-np.mean(np.maximum(lp, -1e3)))

    chosen = min(INVERSE_PENALTIES, key=lambda c: held_out(every[c]))
    logits = every[chosen]

    def log_probs(temperature: float) -> np.ndarray:
        z = logits / temperature
        z = z - z.max(1, keepdims=True)
        with np.errstate(divide="ignore"):
            return z - np.log(np.exp(z).sum(1, keepdims=True))

    def loss(temperature: float) -> float:
        return float(-np.mean(np.maximum(log_probs(temperature)[rows, y], -1e3)))

    temperature = float(minimize_scalar(loss, bounds=(0.05, 20.0), method="bounded").x)
    probs = np.exp(log_probs(temperature))
    freq = np.bincount(y, minlength=n_actions) / len(y)
    out = {"probs": probs, "log_loss": loss(temperature),
           "log_loss_frequencies": float(-np.mean(np.log(freq[y]))),
           "temperature": temperature, "folds": k, "inverse_penalty": chosen}
    out.update(calibration(probs, y))
    return out


def calibration(probs: np.ndarray, actions: np.ndarray, bins: int = BINS) -> dict:
    """{"ece", "calibration": [{predicted, observed, pairs}]}: every (step, action) pair's
    predicted probability against whether that action was logged, in ``bins`` equal-width
    bins; the ECE the pairs-weighted mean |predicted - observed|."""
    p = np.asarray(probs, np.float64)
    hit = np.zeros_like(p)
    hit[np.arange(len(actions)), np.asarray(actions, np.int64)] = 1.0
    which = np.minimum((p * bins).astype(np.int64), bins - 1).ravel()
    count = np.bincount(which, minlength=bins)
    pred = np.bincount(which, weights=p.ravel(), minlength=bins)
    seen = np.bincount(which, weights=hit.ravel(), minlength=bins)
    ok = count > 0
    ece = float(np.sum(np.abs(pred[ok] - seen[ok])) / count.sum())
    table = [{"predicted": float(pred[b] / count[b]), "observed": float(seen[b] / count[b]),
              "pairs": int(count[b])} for b in range(bins) if count[b]]
    return {"ece": ece, "calibration": table}
