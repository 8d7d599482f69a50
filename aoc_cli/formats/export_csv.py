"""A corpus as a CSV log: one row per step, and its column mapping beside it.

Columns: ``id`` (the episode's own id, e.g. the patient, else its index), ``t`` (the step
within the episode), the observations and actions under their names (the spaces' ``names``,
else ``obs_<i>`` / ``act_<i>``; a discrete action is its integer, and when the action space
names each action (``names``, one an action: labels such as ``fluids=2,vaso=0``) the column is
``action`` with its label beside it in ``action_label``), ``reward`` (absent for a
reward-free corpus), ``terminal`` and ``truncated`` (0/1), each tag as its label and each
numeric column (empty where NaN). ``.tsv`` is tab-separated; ``.gz`` is gzip-compressed.

Numbers are written in the shortest text that reads back to the same value: float64 as
Python's ``repr``; float32 as its own shortest text where that, read as float64 and rounded to
float32, gives the value back, else as the float64 text of the value.

Beside ``NAME.csv``, ``NAME.columns.json`` is the ``--columns`` mapping of ``aoc ingest``
(which column plays which role) with the export spec (:mod:`aoc_cli.formats.spec`) under
``aoc``; ``aoc ingest NAME.csv`` finds it and reads the corpus back exactly.

``--static FILE``: a corpus read with ``--static`` keeps its per-patient covariates as the
last observation columns (``static`` in the observation space; text covariates one-hot,
``sex=F``, ``sex=M``). They are written to FILE, one row per id (one-hot groups back to one
text column), and left out of the step rows, as the corpus came in.
"""

from __future__ import annotations

import csv
import glob
import gzip
import json
import os
from pathlib import Path

import numpy as np

from aoc_cli.errors import AocError, param
from aoc_cli.progress import Progress
from aoc_cli.store import CorpusData, action_labels, atomic_path

RESERVED = ("id", "t", "reward", "terminal", "truncated")
CHUNK_ROWS = 100_000


def mapping_path(path: Path) -> Path:
    """``run.csv`` (``.tsv``, ``.csv.gz``, ...) -> ``run.columns.json`` beside it."""
    path = Path(path)
    name = path.name
    for suffix in (".gz", ".csv", ".tsv"):
        if name.lower().endswith(suffix) and len(name) > len(suffix):
            name = name[: -len(suffix)]
    return path.with_name(name + ".columns.json")


def targets(out: Path, static: str | os.PathLike | None) -> list[Path]:
    """The files an export to ``out`` writes."""
    files = [Path(out), mapping_path(out)]
    if static is not None:
        files.append(Path(static))
    if len({os.path.abspath(f) for f in files}) != len(files):
        raise AocError(f"{param('out')} {out} and {param('static')} {static} name the same "
                       "file: give the "
                       "static covariates their own file")
    return files


def float_text(values: np.ndarray, empty_nan: bool = False) -> np.ndarray:
    """(N,) floats -> (N,) str that read back (as float64, then the dtype) to the same values."""
    values = np.asarray(values)
    text = values.astype(str)
    if values.dtype != np.float64:
        back = text.astype(np.float64).astype(values.dtype)
        bad = ~((back == values) | (np.isnan(back) & np.isnan(values)))
        if bad.any():
            text[bad] = values[bad].astype(np.float64).astype(str)
    if empty_nan:
        text[np.isnan(values)] = ""
    return text


def _names(space: dict, dim: int, prefix: str) -> list[str]:
    names = list(space.get("names") or [])
    return names if len(names) == dim else [f"{prefix}_{i}" for i in range(dim)]


def _static_groups(names: list[str], values: np.ndarray, path: Path):
    """Static covariate names and per-episode values (E, d_s) -> [(column, (E,) text)]: a
    run of ``col=level`` one-hot columns becomes one text column; the rest stay numbers."""
    out: list[tuple[str, np.ndarray]] = []
    i = 0
    while i < len(names):
        col, eq, _level = names[i].partition("=")
        j = i + 1
        while eq and j < len(names) and names[j].partition("=")[0] == col:
            j += 1
        block = values[:, i:j]
        levels = [n.partition("=")[2] for n in names[i:j]]
        if eq and np.all((block == 0) | (block == 1)) and np.all(block.sum(axis=1) == 1):
            text = np.array(levels, dtype=object)[np.argmax(block, axis=1)]
            present = sorted(set(text.tolist()))
            if present != levels:
                raise AocError(f"{param('static')} {path}: covariate {col!r} has levels "
                               f"{levels} but "
                               f"the exported patients hold {present}; read back they would "
                               f"not give the same columns: export without {param('static')}")
            out.append((col, text.astype(str)))
        else:
            for k in range(i, j):
                out.append((names[k], float_text(values[:, k])))
        i = j
    return out


def _split_static(data: CorpusData, names: list[str], static: Path):
    """(step observation names, their indices, static columns [(name, (E,) text)])."""
    space = data.observation_space
    stat = list(space.get("static") or [])
    if not stat or names[len(names) - len(stat):] != stat:
        raise AocError(f"{param('static')} {static}: corpus has no per-patient covariates (it "
                       f"was not read with {param('static')}); export without {param('static')}")
    d = len(names) - len(stat)
    obs = np.asarray(data.observations)[:, d:]
    first = obs[np.asarray(data.episode_starts[:-1])]
    lengths = np.diff(data.episode_starts)
    if not np.array_equal(np.repeat(first, lengths, axis=0), obs):
        raise AocError(f"{param('static')} {static}: the covariates change within an episode, "
                       f"so they are not per patient; export without {param('static')}")
    return names[:d], list(range(d)), _static_groups(stat, first.astype(np.float64), static)


def _header(obs_names, act_names, data: CorpusData) -> tuple[list[str], list[str]]:
    """Unique observation and action column names (generic ones where the spaces' names
    clash with each other or with id, t, reward, terminal, truncated, tags, columns)."""
    reserved = {r for r in RESERVED if r != "reward" or data.rewards is not None}
    others = reserved | set(data.tags) | set(data.columns)
    clash = sorted(set(data.tags) & (set(data.columns) | reserved)) or \
        sorted(set(data.columns) & reserved)
    if clash:
        raise AocError(f"a tag or column of the corpus is named {clash[0]!r}, which the CSV "
                       "needs for itself: export to Minari or D4RL instead")
    named = obs_names + act_names
    if len(set(named)) != len(named) or others & set(named):
        obs_names = [f"obs_{i}" for i in range(len(obs_names))]
        act_names = [f"act_{i}" for i in range(len(act_names))]
        if others & set(obs_names + act_names):
            raise AocError("a tag or column of the corpus is named like a generic observation "
                           "or action column (obs_<i>, act_<i>): export to Minari or D4RL")
    return obs_names, act_names


def _open(tmp: Path, target: Path):
    """``tmp`` open for text; gzip-compressed when ``target`` ends in ``.gz``."""
    if target.name.lower().endswith(".gz"):
        return gzip.open(tmp, "wt", encoding="utf-8", newline="")
    return open(tmp, "w", encoding="utf-8", newline="")


def write_csv(data: CorpusData, spec: dict, out: Path, progress: Progress | None = None,
              static: Path | None = None) -> list[Path]:
    """Write ``data`` as ``out`` with its mapping (and ``static``); returns the files."""
    out = Path(out)
    ids = spec["episode_ids"]
    if ids is not None and len(set(ids)) != len(ids):
        raise AocError("the corpus repeats episode ids: a CSV joins rows into episodes by id, "
                       "so they would merge; export to Minari or D4RL instead")
    d_o = np.asarray(data.observations).shape[1]
    obs_names = _names(data.observation_space, d_o, "obs")
    obs_index = list(range(d_o))
    static_cols = None
    if static is not None:
        obs_names, obs_index, static_cols = _split_static(data, obs_names, static)
    discrete = data.discrete
    actions = np.asarray(data.actions)
    labels = action_labels(data.action_space) or []
    labelled = bool(labels)
    act_names = ["action"] if labelled else \
        _names(data.action_space, 1 if discrete else actions.shape[1], "act")
    obs_names, act_names = _header(obs_names, act_names, data)
    lengths = np.diff(data.episode_starts)
    episode_text = np.array(ids if ids is not None else [str(i) for i in range(len(lengths))],
                            dtype=object)
    cols: list[tuple[str, np.ndarray]] = [
        ("id", np.repeat(episode_text, lengths).astype(str)),
        ("t", data.timesteps().astype(str))]
    obs = np.asarray(data.observations)
    cols += [(n, float_text(obs[:, j])) for n, j in zip(obs_names, obs_index)]
    if discrete:
        cols.append((act_names[0], actions.astype(np.int64).astype(str)))
        label_col = f"{act_names[0]}_label"
        if labelled and label_col not in {c for c, _ in cols} | set(data.tags) | \
                set(data.columns) | set(RESERVED):  # read back as text: not a corpus column
            cols.append((label_col, np.array(labels, dtype=object)[actions].astype(str)))
    else:
        cols += [(n, float_text(actions[:, j])) for j, n in enumerate(act_names)]
    if data.rewards is not None:
        cols.append(("reward", float_text(np.asarray(data.rewards, np.float64))))
    cols.append(("terminal", np.asarray(data.terminals, bool).astype(np.uint8).astype(str)))
    cols.append(("truncated", np.asarray(data.truncations, bool).astype(np.uint8).astype(str)))
    for name, (codes, labels) in data.tags.items():
        cols.append((name, np.array(labels, dtype=object)[np.asarray(codes)].astype(str)))
    for name, values in data.columns.items():
        cols.append((name, float_text(np.asarray(values, np.float64), empty_nan=True)))
    delimiter = "\t" if ".tsv" in [s.lower() for s in out.suffixes] else ","
    files = []
    mapping = {"id": "id", "time": "t", "observations": [glob.escape(n) for n in obs_names],
               "actions": [glob.escape(n) for n in act_names],
               "reward": "reward" if data.rewards is not None else None,
               "terminal": "terminal", "tags": list(data.tags), "discrete_actions": discrete}
    if static_cols is not None:
        _write_table(static, ["id"] + [c for c, _ in static_cols],
                     [episode_text.astype(str)] + [v for _, v in static_cols],
                     "\t" if ".tsv" in [s.lower() for s in static.suffixes] else ",", None)
        files.append(static)
        mapping["static"] = os.path.relpath(os.path.abspath(static),
                                            os.path.abspath(mapping_path(out).parent))
    mapping["aoc"] = spec
    with atomic_path(mapping_path(out)) as tmp:
        tmp.write_text(json.dumps(mapping, indent=1) + "\n")
    files.append(mapping_path(out))
    _write_table(out, [c for c, _ in cols], [v for _, v in cols], delimiter, progress)
    return [out] + files


def _write_table(path: Path, header: list[str], columns: list[np.ndarray], delimiter: str,
                 progress: Progress | None) -> None:
    """Header and rows (columns of text, one value a row) to ``path``, atomically."""
    n = len(columns[0]) if columns else 0
    with atomic_path(path) as tmp:
        with _open(tmp, path) as fh:
            writer = csv.writer(fh, delimiter=delimiter, lineterminator="\n")
            writer.writerow(header)
            for a in range(0, n, CHUNK_ROWS):
                block = [c[a:a + CHUNK_ROWS].tolist() for c in columns]
                writer.writerows(zip(*block))
                if progress is not None:
                    progress(min(a + CHUNK_ROWS, n), n, f"writing {path.name}")


__all__ = ["float_text", "mapping_path", "targets", "write_csv"]
