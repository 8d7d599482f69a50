"""Stays cut short (censored) in value targets: no reward of 0 at the cut.

A stay that a clinical ingest marked censored (transferred, still in the unit when the extract
ends, or with no recorded outcome: :mod:`aoc_cli.formats.outcomes`) ends in a truncation whose
outcome is unknown. Its return-to-go stops at the cut, so with the outcome as the last reward
it would read as an outcome of 0. Instead its value at the cut is continued by the stays that
were not censored and were still there at that time (the reasoning of the Kaplan-Meier
estimator: censoring independent of the outcome given the time):

    v_cut(e) = mean of v over the rows of uncensored stays at step T_e      (T_e: e's length)

falling back to their rows at any later step, then to their last rows, when none is at step
T_e; 0 when no stay is complete. ``return`` then adds ``gamma^(T_e - t) v_cut(e)`` to the
return-to-go of each row t of e; ``fqe`` bootstraps e's last row with ``gamma v_cut(e)``
computed from the current Q at every backup. Applied to the corpora whose ingest recorded
censoring (``preprocessing`` with ``outcome`` or ``censored_column``); a time-limit truncation
of a simulator's episode keeps its plain return-to-go (docs/design.md).
"""

from __future__ import annotations

import numpy as np


def censoring_of(corpus) -> np.ndarray | None:
    """(E,) bool: the censored stays of ``corpus`` (truncated, of a corpus whose ingest
    recorded censoring), or None when it records none."""
    manifest = getattr(corpus, "manifest", None) or {}
    pre = manifest.get("preprocessing") or {}
    if "outcome" not in pre and "censored_column" not in pre:
        return None
    starts = np.asarray(corpus.episode_starts)
    censored = np.asarray(corpus.read("truncations"), bool)[starts[1:] - 1]
    return censored if censored.any() else None


def cut_values(values: np.ndarray, episode_starts: np.ndarray,
               censored: np.ndarray) -> np.ndarray:
    """(E,) the value v_cut at each censored stay's cut (module docstring; 0 for the others)
    from per-row ``values`` (N,)."""
    starts = np.asarray(episode_starts, np.int64)
    lengths = np.diff(starts)
    out = np.zeros(len(lengths))
    complete = ~censored
    if not complete.any() or not censored.any():
        return out
    rows = np.repeat(complete, lengths)
    step = np.arange(len(values)) - np.repeat(starts[:-1], lengths)
    width = int(lengths.max()) + 1
    total = np.bincount(step[rows], weights=values[rows], minlength=width)
    count = np.bincount(step[rows], minlength=width).astype(np.float64)
    later_total = np.cumsum(total[::-1])[::-1]  # rows at this step or later
    later_count = np.cumsum(count[::-1])[::-1]
    last = starts[1:][complete] - 1
    fallback = float(np.mean(values[last]))
    for e in np.flatnonzero(censored):
        t = int(lengths[e])
        if count[t] > 0:
            out[e] = total[t] / count[t]
        elif later_count[t] > 0:
            out[e] = later_total[t] / later_count[t]
        else:
            out[e] = fallback
    return out


def censored_return_to_go(v: np.ndarray, episode_starts: np.ndarray, censored: np.ndarray,
                          gamma: float) -> np.ndarray:
    """The return-to-go ``v`` (N,) with each censored stay continued past its cut."""
    starts = np.asarray(episode_starts, np.int64)
    lengths = np.diff(starts)
    cut = cut_values(v, starts, censored)
    to_end = np.repeat(starts[1:], lengths) - np.arange(len(v))  # T_e - t
    rows = np.repeat(censored, lengths)
    out = v.copy()
    out[rows] += gamma ** to_end[rows] * np.repeat(cut, lengths)[rows]
    return out
