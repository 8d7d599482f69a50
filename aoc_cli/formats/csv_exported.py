"""Reading back a CSV that ``aoc export --to csv`` wrote (:mod:`aoc_cli.formats.export_csv`).

Its mapping ``NAME.columns.json`` lies beside it: :func:`exported_mapping` uses it when no
``--columns`` or role flag is given (and the ``static`` file it names, relative to it);
:func:`restore_exported` puts the episodes back in the exported order (the CSV reader orders
them by id), takes the truncations from the ``truncated`` column, then applies the export
spec (:func:`aoc_cli.formats.spec.restore`).
"""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import numpy as np

from aoc_cli.errors import AocError, param
from aoc_cli.formats.common import ReadOptions
from aoc_cli.formats.export_csv import mapping_path
from aoc_cli.formats.spec import restore, take_episodes
from aoc_cli.store import CorpusData


def exported_mapping(path: Path, options: ReadOptions) -> ReadOptions:
    """``options`` with the mapping ``aoc export`` wrote beside ``path`` (when there is one
    holding an export spec and no --columns or role flag is given), and its static file."""
    flags = (options.columns_file, options.obs_columns, options.act_columns,
             options.reward_column, options.id_column, options.time_column,
             options.terminal_column)
    if all(f is None for f in flags) and mapping_path(path).is_file():
        if "aoc" in _load(mapping_path(path)):
            options = dataclasses.replace(options, columns_file=mapping_path(path))
    if options.columns_file is not None and options.static is None:
        static = _load(Path(options.columns_file)).get("static")
        if isinstance(static, str) and static:
            options = dataclasses.replace(
                options, static=Path(options.columns_file).parent / static)
    return options


def _load(path: Path) -> dict:
    """A mapping file's JSON object ({} when unreadable: the CSV reader reports that)."""
    try:
        found = json.loads(Path(path).read_text())
    except (OSError, UnicodeDecodeError, json.JSONDecodeError):
        return {}
    return found if isinstance(found, dict) else {}


def restore_exported(data: CorpusData, spec: dict, path: Path) -> CorpusData:
    """An exported CSV as read -> the corpus that was exported."""
    keys = spec.get("episode_ids") or [str(i) for i in range(spec["episodes"])]
    where = {e: i for i, e in enumerate(data.episode_ids or [])}
    if len(keys) != data.n_episodes or any(k not in where for k in keys):
        raise AocError(f"{path}: its episode ids differ from those of its export metadata "
                       f"(edited after export?); re-export it, or pass {param('columns_file')} "
                       "with your own mapping")
    data = take_episodes(data, np.array([where[k] for k in keys], dtype=np.int64))
    truncated = data.columns.pop("truncated", None)
    if truncated is not None:
        data.truncations = truncated != 0
    return restore(data, spec, path)
