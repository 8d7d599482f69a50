"""A linear (multinomial logistic) probe: how much of a tag a representation makes linearly
readable. Used to check that beliefs identify what the history reveals (e.g. the dynamics
system of pendulum-het) better than (o, a) alone.

    min_{W, c}  (1/n) sum_i -log softmax(W x_i + c)_{y_i} + (l2 / 2) ||W||^2

on standardised features, fitted with L-BFGS (scipy) and an exact gradient.
"""

from __future__ import annotations

import numpy as np
from scipy.optimize import minimize
from scipy.special import log_softmax, softmax


def quadratic_features(x: np.ndarray) -> np.ndarray:
    """(n, d) -> (n, d + d (d + 1) / 2): x and every product x_i x_j (i <= j). A logistic probe
    on these reads what the representation holds as an interaction: a belief that encodes the
    *effective* torque s a and the commanded a holds the system s = sign(a * s a), which no
    linear probe can read."""
    x = np.asarray(x, dtype=np.float64)
    i, j = np.triu_indices(x.shape[1])
    return np.concatenate([x, x[:, i] * x[:, j]], axis=1)


def logistic_probe(train_x: np.ndarray, train_y: np.ndarray, test_x: np.ndarray,
                   test_y: np.ndarray, l2: float = 1e-4, max_iter: int = 500,
                   quadratic: bool = False) -> float:
    """Accuracy on (test_x (M, d), test_y (M,)) of a logistic regression fitted on
    (train_x (n, d), train_y (n,) int labels); with ``quadratic``, on
    :func:`quadratic_features` of both."""
    train_x = np.asarray(train_x, dtype=np.float64)
    test_x = np.asarray(test_x, dtype=np.float64)
    if quadratic:
        train_x, test_x = quadratic_features(train_x), quadratic_features(test_x)
    mean = train_x.mean(0)
    std = np.where(train_x.std(0) > 1e-12, train_x.std(0), 1.0)
    x = (train_x - mean) / std
    classes, y = np.unique(np.asarray(train_y), return_inverse=True)
    n, d = x.shape
    k = len(classes)
    onehot = np.eye(k)[y]

    def objective(theta):
        w = theta[:d * k].reshape(d, k)
        c = theta[d * k:]
        logits = x @ w + c
        logp = log_softmax(logits, axis=1)
        loss = -(onehot * logp).sum() / n + 0.5 * l2 * (w ** 2).sum()
        g = (softmax(logits, axis=1) - onehot) / n
        return loss, np.concatenate([(x.T @ g + l2 * w).ravel(), g.sum(0)])

    if k == 1:
        pred = np.full(len(test_x), classes[0])
    else:
        res = minimize(objective, np.zeros(d * k + k), jac=True, method="L-BFGS-B",
                       options={"maxiter": max_iter})
        w = res.x[:d * k].reshape(d, k)
        c = res.x[d * k:]
        pred = classes[np.argmax(((test_x - mean) / std) @ w + c, axis=1)]
    return float(np.mean(pred == np.asarray(test_y)))
