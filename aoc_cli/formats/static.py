"""Static per-episode covariates of a CSV log (``--static FILE``, one row per episode id),
joined onto every step of the series and appended to its observation: numeric columns as they
are, text columns one-hot (``sex=F``, ``sex=M``, levels from the whole file), tag columns kept
as text for the series' tags. A column named as a column of another role in the series (its
outcome, reward, an action, the censoring or terminal flag, the time) is left out, unless
``allow_role_overlap``: it would leak into the state.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from aoc_cli.errors import AocError, param, warn
from aoc_cli.formats.table import is_numeric, numeric, read_table, text


def read_static(path: Path, id_col: str, episode_keys: np.ndarray, episode_ids: list[str],
                 numeric_ids: bool, tag_cols: list[str], skip=frozenset()):
    """Static per-episode features, one row per id -> (names, (E, d_s) float, tag values);
    the columns ``skip`` (those of another role in the series: its outcome, ...) are not
    features."""
    table = read_table(path, text_columns=[id_col, *tag_cols])
    header, cols = table.header, table.cols
    if id_col not in header:
        raise AocError(f"{param('static')} {path} has no id column {id_col!r} (columns: "
                       f"{', '.join(header)}): name it as in the main file")
    id_text = text(cols[id_col])
    keys = numeric(cols[id_col], id_col, path) if numeric_ids else id_text
    uniq, counts = np.unique(keys, return_counts=True)
    if np.any(counts > 1):
        raise AocError(f"{param('static')} {path} has several rows for id "
                       f"{str(uniq[counts > 1][0])!r}: "
                       "give one row per episode")
    order = np.argsort(keys, kind="stable")
    pos = np.searchsorted(keys[order], episode_keys)
    pos = np.minimum(pos, len(keys) - 1)
    found = keys[order][pos] == episode_keys
    if not found.all():
        missing = episode_ids[int(np.flatnonzero(~found)[0])]
        raise AocError(f"{param('static')} {path} has no row for episode id {missing!r}: add one")
    rows = order[pos]
    unused = len(keys) - len(np.unique(rows))
    if unused:
        extra = sorted(set(range(len(keys))) - set(rows.tolist()))
        warn(f"{param('static')} {path}: {unused} ids have no rows in the series (first: "
             f"{str(id_text[extra[0]])!r}); their static rows are not "
             "used")
    names: list[str] = []
    feats: list[np.ndarray] = []
    tags: dict[str, np.ndarray] = {}
    for c in header:
        if c == id_col or (c in skip and c not in tag_cols):
            continue
        if c in tag_cols:
            tags[c] = text(cols[c])[rows]
        elif is_numeric(cols[c]):
            names.append(c)
            feats.append(numeric(cols[c], c, path)[rows])
        else:  # levels from the whole file, so they do not depend on which ids are present
            levels = text(cols[c])
            for level in sorted(set(levels.tolist())):
                names.append(f"{c}={level}")
                feats.append((levels[rows] == level).astype(np.float64))
    feats_arr = np.stack(feats, axis=1) if feats else np.zeros((len(rows), 0))
    return names, feats_arr, tags
