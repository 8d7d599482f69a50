"""A stay's outcome as its reward, and stays cut short marked as censored.

* ``--outcome died_in_hosp --outcome-reward 1=-1,0=1``: the outcome, constant within the stay,
  becomes the reward of the stay's last step; every other step gets 0 (plus the reward column
  when one is given).
* A stay whose outcome is empty on every row, or that ``--censored-column COL`` marks (a
  truthy cell on any of its rows: transferred, still in the unit when the extract ends), was
  cut short: its last row is a truncation, not a terminal, and it gets no outcome reward. Value
  targets and FQE treat it as censored (no reward of 0 after its cut).
"""

from __future__ import annotations

import numpy as np

from aoc_cli.errors import AocError, param


def parse_rewards(text: str | dict | None) -> dict[float, float] | None:
    """``"1=-1,0=1"`` (or a dict) -> {outcome value: reward}."""
    if text is None:
        return None
    items = text.items() if isinstance(text, dict) else [
        p.split("=", 1) if "=" in p else (p, "") for p in text.split(",") if p.strip()]
    out = {}
    for key, value in items:
        try:
            out[float(key)] = float(value)
        except (TypeError, ValueError):
            raise AocError(f"{param('outcome_reward', text)}: write OUTCOME=REWARD pairs, "
                           "comma-separated, e.g. 1=-1,0=1") from None
    if not out:
        raise AocError(f"{param('outcome_reward', text)} names no outcome")
    return out


def stay_outcomes(values: np.ndarray, starts: np.ndarray, name: str, where,
                  row_label) -> np.ndarray:
    """(E,) the outcome of each stay (NaN: empty on every row, censored) from (N,) row
    values in stay order; an outcome that changes within a stay is an AocError naming the
    row and stay. ``row_label(i)``: text naming corpus row i's stay and file row."""
    stay = np.repeat(np.arange(len(starts) - 1), np.diff(starts))
    present = ~np.isnan(values)
    out = np.full(len(starts) - 1, np.nan)
    rows = np.flatnonzero(present)
    if rows.size == 0:
        return out
    # the first present value of each stay, then every present row compared with it
    first_rows = rows[np.r_[True, stay[rows][1:] != stay[rows][:-1]]]
    out[stay[first_rows]] = values[first_rows]
    differs = rows[values[rows] != out[stay[rows]]]
    if differs.size:
        i = int(differs[0])
        raise AocError(f"{where}: the outcome {name!r} changes within a stay: {row_label(i)} "
                       f"holds {values[i]:g}, the stay's earlier rows "
                       f"{out[stay[i]]:g}; an outcome is one value per stay")
    return out


def outcome_rewards(outcomes: np.ndarray, mapping: dict[float, float], starts: np.ndarray,
                    n: int, name: str, where, stay_label) -> np.ndarray:
    """(N,) rewards: each uncensored stay's mapped outcome on its last row, 0 elsewhere.
    An outcome the mapping does not name is an AocError naming the stay."""
    rewards = np.zeros(n)
    known = np.array(sorted(mapping))
    for e in np.flatnonzero(~np.isnan(outcomes)):
        if outcomes[e] not in mapping:
            raise AocError(f"{where}: the outcome {name!r} of {stay_label(int(e))} is "
                           f"{outcomes[e]:g}, which {param('outcome_reward')} does not map "
                           f"(it maps {', '.join(f'{k:g}' for k in known)})")
    last = starts[1:] - 1
    has = ~np.isnan(outcomes)
    rewards[last[has]] = [mapping[v] for v in outcomes[has]]
    return rewards


def censored_stays(values: np.ndarray, starts: np.ndarray) -> np.ndarray:
    """(E,) bool: stays with a truthy (non-zero) cell of the censoring column."""
    truthy = np.nan_to_num(values, nan=0.0) != 0
    return np.logical_or.reduceat(truthy, starts[:-1]) if len(values) else \
        np.zeros(len(starts) - 1, bool)


def mark_censored(censored: np.ndarray, terminals: np.ndarray, truncations: np.ndarray,
                  starts: np.ndarray) -> None:
    """The last row of each censored stay becomes a truncation, not a terminal (in place)."""
    last = starts[1:] - 1
    terminals[last[censored]] = False
    truncations[last[censored]] = True
