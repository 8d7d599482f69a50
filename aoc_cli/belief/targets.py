"""Value targets v^c: the performance measure each corpus row is trained to predict.

* ``return``: discounted return-to-go ``v_t = sum_{k = t}^{T_e - 1} gamma^(k - t) r_k`` within
  the row's own episode e (rows ``[s_e, T_e)``). At a truncated (time-limit) or cut-off episode
  end this is just the sum of the remaining discounted rewards *within the logged episode*: there
  is no bootstrapping from a value estimate, so no model enters the target.
* ``mean-return``: the mean of the remaining rewards ``(1 / (T_e - t)) sum_{k = t}^{T_e - 1} r_k``.
* ``reward``: the immediate reward ``r_t``.
* ``fqe``: the logged behaviour's action value ``Q(o_t, a_t)`` by fitted Q evaluation with
  expected SARSA targets ``r_t + gamma V(o_{t+1})``, V(o) the mean of Q(o, a) over the log's
  rows at o (bootstrapped through the log's own next steps; :mod:`aoc_cli.belief.fqe`).
* ``neighbours``: the same with the mean of the log's rows near an observation (rule 7's sets)
  as the regressor in place of a network (a nearest-neighbour FQE, rule 7's values:
  :func:`aoc_cli.index.search.neighbourhood.neighbourhood_values`): what the log itself says
  near a noisy observation, a smooth target where the return of one stay is mostly noise.
* any other name: a numeric per-row column of the corpus, used as is.
"""

from __future__ import annotations

import hashlib
import json

import numpy as np

from aoc_cli.belief.censoring import censored_return_to_go, censoring_of
from aoc_cli.belief.config import REWARD_TARGETS, FQEConfig
from aoc_cli.errors import BadSetting, NoRewards, param
from aoc_cli.index.search.neighbourhood import (fitted_values, measured_cells,
                                                neighbourhood_values)
from aoc_cli.store import hash_arrays, targets_dir, write_json, write_npy

#: Padded cells allowed per group of episodes of similar length (beyond 4x the real rows).
_GROUP_CELLS = 1 << 22


def discounted_return_to_go(rewards: np.ndarray, episode_starts: np.ndarray,
                            gamma: float) -> np.ndarray:
    """(N,) float64 ``sum_{k >= t, same episode} gamma^(k - t) r_k`` for rewards (N,).

    Episodes of similar length are padded into a matrix (zeros after the end contribute
    nothing) and filtered in reverse with one ``lfilter`` call per group: no Python per row.
    """
    from scipy.signal import lfilter  # imported here: scipy.signal is slow to import

    rewards = np.asarray(rewards, dtype=np.float64)
    starts = np.asarray(episode_starts, dtype=np.int64)
    lengths = np.diff(starts)
    out = np.empty_like(rewards)
    order = np.argsort(lengths, kind="stable")
    i = 0
    while i < len(order):
        # Grow the group while the padded matrix stays small relative to its real rows.
        j = i + 1
        total = int(lengths[order[i]])
        while j < len(order):
            longest = int(lengths[order[j]])
            if (j - i + 1) * longest > max(4 * (total + longest), _GROUP_CELLS):
                break
            total += longest
            j += 1
        group = order[i:j]
        g_len = lengths[group]
        width = int(g_len.max())
        col = np.arange(width)
        inside = col[None, :] < g_len[:, None]                       # (G, W)
        rows = starts[group][:, None] + np.where(inside, col[None, :], 0)
        mat = np.where(inside, rewards[rows], 0.0)
        ret = lfilter([1.0], [1.0, -gamma], mat[:, ::-1], axis=1)[:, ::-1]
        out[rows[inside]] = ret[inside]
        i = j
    return out


def mean_remaining_reward(rewards: np.ndarray, episode_starts: np.ndarray) -> np.ndarray:
    """(N,) float64 mean of the rewards from each row to the end of its episode."""
    starts = np.asarray(episode_starts, dtype=np.int64)
    lengths = np.diff(starts)
    ends = np.repeat(starts[1:], lengths)
    remaining = ends - np.arange(len(rewards))
    return discounted_return_to_go(rewards, starts, 1.0) / remaining


def value_targets(corpus, value: str, gamma: float, progress=None) -> np.ndarray:
    """(N,) float64 value target v of every row of ``corpus`` (see the module docstring);
    ``progress`` (:mod:`aoc_cli.progress`) follows ``fqe``'s backups."""
    if value in REWARD_TARGETS:
        if not corpus.has_rewards:
            raise NoRewards(
                corpus.name, f"value {value}",
                f"corpus {corpus.name!r} has no rewards, so {param('value', value)} cannot be "
                f"computed: use {param('mode', 'imitation')} (or {param('value', 'COLUMN')} "
                "with a numeric column of the corpus)")
        rewards = corpus.rewards
        if value == "reward":
            v = np.asarray(rewards, dtype=np.float64).copy()
        elif value == "fqe":
            from aoc_cli.belief.fqe import fitted_q_values  # lazy: torch, for fqe targets only

            v = fitted_q_values(corpus.observations, corpus.actions, rewards,
                                corpus.episode_starts, gamma,
                                n_actions=corpus.n_actions if corpus.discrete else None,
                                progress=progress, censored=censoring_of(corpus))
        elif value == "neighbours":
            v = neighbourhood_targets(corpus, gamma, progress)[0]
        elif value == "mean-return":
            v = mean_remaining_reward(rewards, corpus.episode_starts)
        else:
            v = discounted_return_to_go(rewards, corpus.episode_starts, gamma)
            censored = censoring_of(corpus)
            if censored is not None:
                v = censored_return_to_go(v, corpus.episode_starts, censored, gamma)
    else:
        columns = list(corpus.manifest.get("columns", []))
        if value not in columns:
            known = ", ".join(columns) or "none"
            raise BadSetting(
                "value", value,
                f"unknown {param('value')} {value!r}: use return, mean-return, reward, fqe, "
                f"neighbours or a numeric column of corpus {corpus.name!r} (columns: {known})")
        v = np.asarray(corpus.column(value), dtype=np.float64).copy()
    bad = ~np.isfinite(v)
    if bad.any():
        raise BadSetting(
            "value", value,
            f"{param('value', value)} is not finite (NaN or inf) in {int(bad.sum())} rows, "
            f"first row {int(np.flatnonzero(bad)[0])}: choose another {param('value')} or fix "
            "the column")
    return v


#: The value targets :func:`held_out_targets` keeps on disk: those that fit a model.
KEPT_TARGETS = ("fqe",)


def held_out_targets(corpus, value: str, gamma: float, progress=None) -> np.ndarray:
    """(N,) :func:`value_targets` of a corpus used as a held-out log (``aoc evaluate``'s
    value target, where no other estimate is given), computed once and kept beside it
    (:func:`kept_values`): a fitted Q evaluation of a held-out log costs what fitting the model's
    own values did (60 backups of gradient steps; docs/notes/benchmarks-rounds.md, "Figures once in
    docstrings"). The other targets cost a pass over the rewards and are not kept."""
    if value not in KEPT_TARGETS:
        return value_targets(corpus, value, gamma, progress=progress)
    import torch  # lazy: torch, for fqe targets only (its version is part of the record)

    record = {"value": value, "gamma": float(gamma), "fqe": FQEConfig().to_dict(),
              "torch": torch.__version__}
    return kept_values(corpus, value, record,
                       lambda: value_targets(corpus, value, gamma, progress=progress))


def kept_values(corpus, name: str, record: dict, compute) -> np.ndarray:
    """(N,) float64 ``compute()`` for the rows of ``corpus``, computed once and kept beside
    it, in ``<corpus>/targets/`` (:func:`aoc_cli.store.targets_dir`), under ``name`` with what
    they were computed from: ``record`` (JSON: the settings and versions), the corpus's
    content hash and row count, and the array's own hash. They are read back only when all of
    it matches (anything else, a damaged or half-read file included, computes them anew and
    rewrites them). A store that cannot be written, or a corpus with no path or hash, is no
    error: the values are then computed each time."""
    path = getattr(corpus, "path", None)
    if path is None or not getattr(corpus, "hash", None):
        return np.asarray(compute(), np.float64)
    record = {"corpus": corpus.hash, "rows": int(corpus.n_rows), **record}
    key = hashlib.sha256(json.dumps(record, sort_keys=True).encode()).hexdigest()[:16]
    folder = targets_dir(path)
    npy, meta = folder / f"{name}-{key}.npy", folder / f"{name}-{key}.json"
    kept = _read_kept(npy, meta, record)
    if kept is not None:
        return kept
    v = np.asarray(compute(), np.float64)
    if v.shape != (record["rows"],):
        raise ValueError(f"{name}: {v.shape} values for {record['rows']} rows")
    try:
        write_npy(npy, v)
        write_json(meta, {**record, "values": hash_arrays(v)})
    except OSError:
        pass            # a read-only store: computed again next time
    return v


def _read_kept(npy, meta, record: dict) -> np.ndarray | None:
    """The kept targets when their record matches ``record`` and their bytes their hash."""
    want = json.loads(json.dumps(record))       # as JSON reads it back
    try:
        got = json.loads(meta.read_text())
        if {k: got.get(k) for k in want} != want:
            return None
        v = np.load(npy, allow_pickle=False)
    except (OSError, ValueError):
        return None
    if v.dtype != np.float64 or v.shape != (record["rows"],) or \
            hash_arrays(v) != got.get("values"):
        return None
    return v


def neighbourhood_targets(corpus, gamma: float, progress=None
                          ) -> tuple[np.ndarray, np.ndarray, dict | None]:
    """(fitted (N,), one-step (N,), space): the ``neighbours`` targets of ``corpus``, FQE over
    the log's neighbourhoods: the fitted values, the belief's target, the one-step values
    rule 7 reads, and what its sets were built from (saved with the model;
    :func:`aoc_cli.index.search.neighbourhood.neighbourhood_values`)."""
    step, info = neighbourhood_values(corpus.observations, corpus.rewards,
                                      corpus.episode_starts, gamma, censoring_of(corpus),
                                      progress=progress, measured=measured_cells(corpus))
    return fitted_values(step, corpus.actions, info["rows"]), step, info["space"]


def value_spec(value: str, gamma: float) -> dict:
    """How v was computed, as recorded in the model's config.json."""
    spec: dict = {"target": value}
    if value == "fqe":
        spec["gamma"] = gamma
        spec["definition"] = ("the logged behaviour's Q(o, a) by fitted Q evaluation "
                              "(expected SARSA targets through the log's next "
                              "observations)")
        spec["fqe"] = FQEConfig().to_dict()
    elif value == "neighbours":
        spec["gamma"] = gamma
        spec["definition"] = ("the logged behaviour's Q(o, a) by fitted Q evaluation over "
                              "the log's neighbourhoods (the regressor the mean over the "
                              "rows near the observation that took the action)")
    elif value == "return":
        spec["gamma"] = gamma
        spec["definition"] = ("discounted return-to-go within the logged episode, "
                              "no bootstrapping at truncated ends (a censored stay of a "
                              "clinical ingest: continued by the stays present at its cut)")
    elif value == "mean-return":
        spec["definition"] = "mean of the remaining rewards of the episode"
    elif value == "reward":
        spec["definition"] = "immediate reward"
    else:
        spec["definition"] = f"corpus column {value!r}"
    return spec
