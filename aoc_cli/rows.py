"""Row masks and multiplicities from a corpus's tags, episodes and row ranges, and the
distinct rows of an array (:func:`distinct_rows`).

A selection (:func:`row_selection`) is an (N,) bool mask over corpus rows that the controller
applies at query time, with no rebuild; a multiplicity (:func:`episode_multiplicity`) is the
(N,) int count of copies of each row in a derived (re-sampled or sub-sampled) index.

Two rates, two names. An *episode rate* (``build_index(episode_rates=...)``, ``aoc index
--episode-rate``) keeps or repeats whole episodes of a tag value: 0.5 keeps half of its
episodes. A *row rate* (:meth:`aoc_cli.index.search.BeliefIndex.resample`, the index layer, which
knows rows, not episodes) samples single index positions: 0.5 keeps half of the positions.
"""

from __future__ import annotations

import numpy as np

from aoc_cli.errors import AocError


def episode_multiplicity(corpus, episode_rates: dict | None, seed: int) -> np.ndarray:
    """(N,) int copies of each corpus row in a derived index, from episode rates
    ``{"policy=pi1": 4.0}``.

    Rates are per tag value: an integer part repeats the rows, a fractional part keeps that
    fraction of whole episodes (chosen with ``seed``), so trajectories stay whole. The counts
    are integers: :meth:`aoc_cli.index.search.BeliefIndex.resample` then only repeats or drops rows
    (its own fractional row rates, which sample single rows, are not used here).
    """
    n = corpus.n_rows
    counts = np.ones(n, dtype=np.int64)
    rng = np.random.default_rng(seed)
    for key, rate in (episode_rates or {}).items():
        tag, _, label = key.partition("=")
        codes, labels = corpus.tag(tag)
        if label not in labels:
            raise AocError(f"tag {tag!r} has no value {label!r} (values: {', '.join(labels)})")
        if rate < 0:
            raise AocError(f"an episode rate must be >= 0, got {rate} for {key}")
        mask = codes == labels.index(label)
        whole, frac = int(np.floor(rate)), rate - np.floor(rate)
        episodes = np.unique(corpus.episode_of(np.flatnonzero(mask)))
        extra = np.zeros(corpus.n_episodes, bool)
        if frac > 0:
            pick = rng.choice(len(episodes), size=int(round(frac * len(episodes))), replace=False)
            extra[episodes[pick]] = True
        per_row = whole + extra[corpus.episode_of(np.arange(n))].astype(np.int64)
        counts[mask] = per_row[mask]
    if counts.sum() == 0:
        raise AocError("the sampling rates leave no rows in the index")
    return counts


def row_selection(corpus, select: dict[str, list[str]] | None = None,
                  exclude: dict[str, list[str]] | None = None,
                  episodes: list[int] | None = None,
                  row_range: tuple[int, int] | None = None) -> np.ndarray | None:
    """(N,) bool mask from tag selections/exclusions, episodes and a row range; None = all."""
    if not (select or exclude or episodes or row_range):
        return None
    n = corpus.n_rows
    mask = np.ones(n, bool)
    for tag, labels in (select or {}).items():
        codes, known = corpus.tag(tag)
        for label in labels:
            if label not in known:
                raise AocError(f"tag {tag!r} has no value {label!r} (values: {', '.join(known)})")
        mask &= np.isin(codes, [known.index(x) for x in labels])
    for tag, labels in (exclude or {}).items():
        codes, known = corpus.tag(tag)
        mask &= ~np.isin(codes, [known.index(x) for x in labels if x in known])
    if episodes:
        mask &= np.isin(corpus.episode_of(np.arange(n)), episodes)
    if row_range:
        lo, hi = row_range
        rng_mask = np.zeros(n, bool)
        rng_mask[max(lo, 0):min(hi, n)] = True
        mask &= rng_mask
    if not mask.any():
        raise AocError("the row selection leaves no rows of the corpus")
    return mask


def distinct_rows(a: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(first (U,), inverse (N,)) of the N rows of ``a`` (N, ...) compared as bytes (one
    sort): the first row of each distinct one, in the rows' byte order, and each row's
    index among them (``a[first][inverse]`` is ``a``)."""
    if len(a) == 0:
        return np.empty(0, np.int64), np.empty(0, np.int64)
    a = np.ascontiguousarray(a).reshape(len(a), -1)
    keys = a.view(np.dtype((np.void, a.dtype.itemsize * a.shape[1]))).ravel()
    _, first, inverse = np.unique(keys, return_index=True, return_inverse=True)
    return np.asarray(first, np.int64), np.asarray(inverse, np.int64).reshape(-1)
