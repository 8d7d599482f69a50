"""The cohort notes' shared pieces (``cohort_neighbourhoods.py``, ``cohort_denoised.py``): the
table in memory with its hidden state, each column's spread among near rows, the rule's choice,
and the rule over every row within a radius."""

from __future__ import annotations

import numpy as np

# internal: the table's hidden state and rule 7's neighbourhoods
import aoc_cli.envs.icu_cohort as cohort
from aoc_cli.index.search.denoise import near_row_spread

N_ACTIONS = 25


def table(stays: int, noise: float, seed: int) -> dict:
    """The cohort's rows with the gaps held forward, one-step rewards and the hidden state."""
    cols = cohort.cohort_table(stays, noise, seed=seed)
    ids = cols["id"]
    n = len(ids)
    starts = np.r_[0, np.nonzero(np.diff(ids))[0] + 1, n]
    x = np.stack([cols[c] for c in cohort.OBS_COLUMNS], 1).astype(np.float64)
    measured = ~np.isnan(x)
    last = starts[1:] - 1
    died = cols["died_in_hosp"][last]
    reward = np.zeros(n)
    reward[last] = np.where(np.isnan(died), 0.0, 1.0 - np.nan_to_num(died))
    return {"x": cohort.hold_forward(x, starts), "a": cols["act_dose"].astype(np.int64),
            "state": cols["state"].astype(np.int64), "r": reward, "starts": starts,
            "censored": np.isnan(died), "measured": measured,
            "episode": np.repeat(np.arange(len(last)), np.diff(starts))}


#: each feature's spread among near rows (rule 7's unit; the notes' name for it)
local_spread = near_row_spread


def kept_or_best(low: np.ndarray, likely: np.ndarray) -> np.ndarray:
    """Rule 7's choice from the bounds (S, K) and the likely dose (S,)."""
    best = low.argmax(1)
    s = np.arange(len(low))
    return np.where(low[s, best] > low[s, likely], best, likely)


def successor(t: dict) -> tuple[np.ndarray, np.ndarray]:
    """((N,) each row's next row, (N,) whether its value counts): none after a stay's last
    row; a cut stay's last row its own successor (the stay goes on)."""
    n = len(t["r"])
    going = np.ones(n, bool)
    last = t["starts"][1:] - 1
    going[last] = False
    nxt = np.minimum(np.arange(1, n + 1), n - 1)
    cut = last[t["censored"]]
    nxt[cut], going[cut] = cut, True
    return nxt, going


def radius_rule(t: dict, near: tuple, search, c: float, z: float, least: int = 30,
                radius: float | None = None):
    """(policy, purity) of the rule over every row within c times the log's median squared
    distance to its 10th nearest row (at least ``least`` rows; ``dist`` squared, as FAISS and
    the masked index give it): ``near`` (dist, rows) (N, cap) each logged row's nearest,
    ``search(obs (S, d), measured (S, d)) -> (dist, rows)`` the step's; rows valued by FQE over
    these sets; z the bound's; ``radius`` (squared) in place of c's where given.
    ``policy.size``: the sets' median size."""
    a, ep, n = t["a"], t["episode"], len(t["x"])
    dist, rows = near
    if radius is None:
        radius = c * float(np.median(dist[:, min(9, dist.shape[1] - 1)]))

    def inside(d):
        ok = d <= radius
        ok[:, :least] = True
        return ok
    ok = inside(dist)
    purity = float(((t["state"][rows] == t["state"][:, None]) & ok).sum() / ok.sum())
    nxt, going = successor(t)
    y, size = np.zeros(n), ok.sum(1)
    for _ in range(1000):
        new = t["r"] + np.where(going, ((y[rows] * ok).sum(1) / size)[nxt], 0.0)
        done = np.abs(new - y).max() < 1e-4
        y = new
        if done:
            break
    span = int(ep.max()) + 1

    def groups(r, keep):
        """(rows, episodes, mean value) per action (S, K) over the kept rows."""
        s, acts = len(r), a[r]
        at = (np.repeat(np.arange(s), r.shape[1]), acts.ravel())
        count, total = np.zeros((s, N_ACTIONS)), np.zeros((s, N_ACTIONS))
        np.add.at(count, at, keep.ravel())
        np.add.at(total, at, (y[r] * keep).ravel())
        key = np.sort(np.where(keep, acts * span + ep[r], -1), axis=1)
        first = key >= 0
        first[:, 1:] &= key[:, 1:] != key[:, :-1]
        episodes = np.zeros((s, N_ACTIONS))
        q, j = np.nonzero(first)
        np.add.at(episodes, (q, key[q, j] // span), 1)
        mean = np.divide(total, count, out=np.zeros((s, N_ACTIONS)), where=count > 0)
        return count, episodes, mean
    pick = np.sort(np.random.default_rng(0).choice(n, min(2000, n), replace=False))
    count, _, mean = groups(rows[pick], ok[pick])
    dev = np.where(ok[pick], (y[rows[pick]] - mean[np.arange(len(pick))[:, None],
                                                   a[rows[pick]]]) ** 2, 0.0)
    sigma = float(np.sqrt(dev.sum() / np.maximum(count - 1, 0).sum()))

    class Policy:
        size = int(np.median(ok.sum(1)))

        def reset(self, episodes):
            pass

        def __call__(self, obs, alive, measured):
            d, r = search(obs, measured)
            count, episodes, mean = groups(r, inside(d))
            with np.errstate(divide="ignore"):
                low = np.where(episodes > 0, mean - z * sigma / np.sqrt(episodes), -np.inf)
            return kept_or_best(low, count.argmax(1))
    return Policy(), purity
