"""What is in the store: the data behind ``aoc info`` and ``aoc ls``.

A model folder ``models/<id>/`` counts as built from the corpus; its ``config.json`` records
``corpus_hash``, the content hash of the corpus it was built from. It is ``ok`` when that
equals the corpus's hash now, ``stale`` when it does not (the corpus was re-ingested or
appended to: rebuild it), ``damaged`` when its config or a file it records is damaged,
``unknown`` when the folder has no config.
"""

from __future__ import annotations

import json

import numpy as np

from aoc_cli.errors import AocError
from aoc_cli.store.atomic import seal_status
from aoc_cli.store.reader import Corpus
from aoc_cli.store.store import Store
from aoc_cli.store.verify import file_status


def space_text(space: dict) -> str:
    """``box(17)``, ``discrete(3)``."""
    if space.get("type") == "discrete":
        return f"discrete({space.get('n')})"
    return f"{space.get('type', '?')}({', '.join(str(s) for s in space.get('shape', []))})"


def built_from(corpus: Corpus) -> list[dict]:
    """One record per folder under ``models/``: id, status, what it holds.

    Status: ``ok``; ``stale`` (built from another version of the corpus: rebuild it);
    ``damaged`` (its config.json unreadable or changed, or a file it records missing, of
    another size, or, when small, with another SHA-256: ``aoc verify`` checks everything);
    ``unknown`` (no config). Records: ``{"id", "status", "corpus_hash", "mode", "files"}``.
    """
    out = []
    if not corpus.models_dir.is_dir():
        return out
    for folder in sorted(p for p in corpus.models_dir.iterdir()
                         if p.is_dir() and not p.name.startswith(".")):
        config, readable = {}, True
        try:
            config = json.loads((folder / "config.json").read_text())
            if not isinstance(config, dict):
                config, readable = {}, False
        except FileNotFoundError:
            pass
        except (OSError, UnicodeDecodeError, json.JSONDecodeError):
            readable = False
        recorded = config.get("corpus_hash")
        status = "unknown" if not recorded else ("ok" if recorded == corpus.hash else "stale")
        files = config.get("files") or {}
        if not readable or seal_status(config) is False or any(
                file_status(folder / name, record, full=False)[0] in ("damaged", "missing")
                for name, record in files.items()):
            status = "damaged"
        out.append({
            "id": folder.name,
            "status": status,
            "corpus_hash": recorded,
            "mode": config.get("mode"),
            "files": sorted(p.name for p in folder.iterdir() if not p.name.startswith(".")),
        })
    return out


def summarize(corpus: Corpus) -> dict:
    """Everything ``aoc info`` shows about a corpus, as one JSON-able object.

    Keys: name, rows, episodes, observation_dim, action_dim, discrete, n_actions,
    has_rewards, return_mean, return_std, return_min, return_max, episode_length_mean/min/max,
    tags ({tag: {label: rows}}), columns, observation_space, action_space, content_hash,
    written, sources, built (see :func:`built_from`); for a corpus read from a clinical table,
    preprocessing (the imputation rule and medians, dose-bin edges, outcome, split),
    imputed_cells ({column: cells}) and censored_episodes.
    """
    returns = corpus.episode_returns()
    lengths = np.diff(corpus.episode_starts)
    tags = {}
    for name in corpus.manifest.get("tags", {}):
        codes, labels = corpus.tag(name)
        counts = np.bincount(np.asarray(codes), minlength=len(labels))
        tags[name] = {label: int(c) for label, c in zip(labels, counts)}

    def stat(fn, arr):
        return None if arr is None or len(arr) == 0 else float(fn(arr))

    return {
        "name": corpus.name,
        "rows": corpus.n_rows,
        "episodes": corpus.n_episodes,
        "observation_dim": corpus.observation_dim,
        "action_dim": corpus.action_dim,
        "discrete": corpus.discrete,
        "n_actions": corpus.n_actions,
        "has_rewards": corpus.has_rewards,
        "return_mean": stat(np.mean, returns),
        "return_std": stat(np.std, returns),
        "return_min": stat(np.min, returns),
        "return_max": stat(np.max, returns),
        "episode_length_mean": stat(np.mean, lengths),
        "episode_length_min": stat(np.min, lengths),
        "episode_length_max": stat(np.max, lengths),
        "tags": tags,
        "columns": list(corpus.manifest.get("columns", [])),
        "observation_space": corpus.observation_space,
        "action_space": corpus.action_space,
        "content_hash": corpus.hash,
        "written": corpus.manifest.get("written"),
        "sources": corpus.manifest.get("sources", []),
        "built": built_from(corpus),
        **clinical_summary(corpus),
    }


def clinical_summary(corpus: Corpus) -> dict:
    """``preprocessing``, ``imputed_cells`` ({column: cells filled}) and
    ``censored_episodes`` (stays whose last row is a truncation) of a corpus that has a
    preprocessing; {} otherwise."""
    pre = corpus.preprocessing
    if not pre:
        return {}
    mask = corpus.imputed_mask
    names = corpus.observation_space.get("names") or []
    cells = {} if mask is None else {
        n: int(c) for n, c in zip(names, mask.sum(axis=0)) if c}
    last = corpus.episode_starts[1:] - 1
    return {"preprocessing": pre, "imputed_cells": cells,
            "censored_episodes": int(np.asarray(corpus.read("truncations"))[last].sum())}


def list_corpora(store: Store) -> list[dict]:
    """One record per corpus: name, status (ok, or damaged: an unreadable or missing manifest,
    a corpus file of the wrong size; ``aoc verify`` says more), rows, episodes, observation,
    action, has_rewards, models."""
    out = []
    for name in sorted(store.names() + store.damaged_names()):
        try:
            c = store.corpus(name)
            out.append({"name": name, "status": "ok", "rows": c.n_rows,
                        "episodes": c.n_episodes,
                        "observation": space_text(c.observation_space),
                        "action": space_text(c.action_space),
                        "has_rewards": c.has_rewards,
                        "models": len(built_from(c))})
        except (AocError, OSError, ValueError, KeyError):
            out.append({"name": name, "status": "damaged", "rows": None, "episodes": None,
                        "observation": None, "action": None, "has_rewards": None,
                        "models": None})
    return out
