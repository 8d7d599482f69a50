"""`aoc index`: the belief of every corpus row and the nearest-neighbour index over them.

Layout under ``<corpus>/models/<model>/``::

    beliefs.npy                 (N, d_b) float32, memory-mappable, the belief of every row
    index/<index_id>/index.faiss    the FAISS index (+ .json, its config)
    index/<index_id>/index.faiss.rows.npy  (M,) int64: entry -> corpus row (derived indexes)
    index/<index_id>/index.json     what it was built from (corpus, model hashes), kind, size

The ``default`` index holds every row once. Derived indexes re-sample or sub-sample rows by
tag (the paper's adaptivity experiment) with no retraining: ``--resample policy=pi1:4``
repeats pi1's rows four times, ``--subsample policy=pi1:0.5`` keeps a random half of them.
"""

from __future__ import annotations

import json
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from aoc_cli.decompose import decompose
from aoc_cli.errors import AocError
from aoc_cli.index import BeliefIndex
from aoc_cli.store import check_name, write_json, write_npy

#: Rows sampled to measure the corpus's typical residual (leave-those-rows-out).
TYPICAL_SAMPLE = 500


@dataclass
class CorpusIndex:
    """A built index: model, beliefs of every corpus row (N, d_b), row values (N,), the FAISS
    index (possibly derived: re-sampled or sub-sampled rows) and what it was built from."""

    index_id: str
    model: object
    beliefs: np.ndarray
    values: np.ndarray | None
    index: BeliefIndex
    meta: dict

    @property
    def typical_residual(self) -> float | None:
        return self.meta.get("typical_residual", {}).get("p50")

    @property
    def rows(self) -> np.ndarray:
        """(M,) the corpus row of every index entry (repeats when re-sampled)."""
        return self.index.row_of

    def decompose(self, queries: np.ndarray, k: int | None = None,
                  selection: np.ndarray | None = None):
        """Decompose query beliefs (Q, d_b) over the corpus; ``rows`` are corpus rows.

        ``selection`` is an (N,) bool mask over corpus rows, applied at query time.
        """
        queries = np.asarray(queries, dtype=np.float32)
        if queries.ndim != 2 or queries.shape[1] != self.beliefs.shape[1]:
            raise AocError(f"queries must be (Q, {self.beliefs.shape[1]}) beliefs, got "
                           f"{queries.shape}")
        return decompose(self.beliefs, queries, k=k, values=self.values, index=self.index,
                         selection=selection)


def _load_model(corpus, model_id: str | None):
    """The model to index or control with: the given id, else "default", else the latest."""
    from aoc_cli.belief import list_models, load_model

    if model_id is None and "default" in list_models(corpus):
        model_id = "default"
    return load_model(corpus, model_id)


def _index_dir(corpus, model_id: str, index_id: str) -> Path:
    return corpus.models_dir / model_id / "index" / check_name(index_id, "index")


def build_index(corpus, model_id: str | None = None, kind: str = "auto",
                index_id: str = "default", resample: dict | None = None,
                subsample: dict | None = None, seed: int = 0, progress=None,
                **params) -> CorpusIndex:
    """Compute (or reuse) the beliefs of every row and build an index over them."""
    model = _load_model(corpus, model_id)
    model_dir = corpus.models_dir / model.id
    beliefs_path = model_dir / "beliefs.npy"
    meta_path = model_dir / "beliefs.json"
    fresh = meta_path.is_file() and json.loads(meta_path.read_text()).get("model_hash") == \
        model.hash and beliefs_path.is_file()
    if not fresh:
        callback = None
        if progress is not None:
            task = progress.add_task("beliefs of every row", total=corpus.n_rows)

            def callback(done, total):
                progress.update(task, completed=done, total=total)
        beliefs = model.row_beliefs(corpus, progress=callback).astype(np.float32)
        write_npy(beliefs_path, beliefs)
        write_json(meta_path, {"model_hash": model.hash, "corpus_hash": corpus.hash,
                               "shape": list(beliefs.shape)})
    beliefs = np.load(beliefs_path, mmap_mode="r", allow_pickle=False)
    if (resample or subsample) and index_id == "default":
        raise AocError("a re-sampled or sub-sampled index needs its own --index-id "
                       "(the default index holds every row once)")
    start = time.perf_counter()
    index = BeliefIndex.build(beliefs, kind=kind, seed=seed, **params)
    if resample or subsample:
        index = index.resample(row_multiplicity(corpus, resample, subsample, seed))
    seconds = time.perf_counter() - start
    out = _index_dir(corpus, model.id, index_id)
    out.mkdir(parents=True, exist_ok=True)
    index.save(out / "index.faiss")
    meta = {
        "index_id": index_id, "model": model.id, "model_hash": model.hash,
        "corpus": corpus.name, "corpus_hash": corpus.hash, "kind": index.kind,
        "rows": int(index.size), "belief_dim": int(beliefs.shape[1]),
        "resample": resample or {}, "subsample": subsample or {}, "seed": seed,
        "build_seconds": seconds, "built": time.strftime("%Y-%m-%dT%H:%M:%S%z"),
    }
    ci = CorpusIndex(index_id, model, beliefs, model.values, index, meta)
    meta["typical_residual"] = typical_residual(ci, seed)
    write_json(out / "index.json", meta)
    return ci


def typical_residual(ci: CorpusIndex, seed: int = 0) -> dict:
    """Residual quantiles of sampled corpus rows decomposed against the other rows."""
    n = len(ci.beliefs)
    if n < 3:
        return {}
    rng = np.random.default_rng(seed)
    sample = rng.choice(n, size=min(TYPICAL_SAMPLE, n // 2), replace=False)
    selection = np.ones(n, bool)
    selection[sample] = False
    dec = ci.decompose(np.asarray(ci.beliefs[np.sort(sample)]), selection=selection)
    r = dec.residual
    return {"p50": float(np.quantile(r, 0.5)), "p90": float(np.quantile(r, 0.9)),
            "p99": float(np.quantile(r, 0.99)), "sample": int(len(sample))}


def row_multiplicity(corpus, resample: dict | None, subsample: dict | None,
                     seed: int) -> np.ndarray:
    """(N,) int copies of each corpus row in a derived index, from ``{"policy=pi1": 4.0}``.

    Rates are per tag value: an integer part repeats the rows, a fractional part keeps that
    fraction of whole episodes (chosen with ``seed``), so trajectories stay whole.
    """
    n = corpus.n_rows
    counts = np.ones(n, dtype=np.int64)
    rng = np.random.default_rng(seed)
    rates = {**(resample or {}), **(subsample or {})}
    for key, rate in rates.items():
        tag, _, label = key.partition("=")
        codes, labels = corpus.tag(tag)
        if label not in labels:
            raise AocError(f"tag {tag!r} has no value {label!r} (values: {', '.join(labels)})")
        if rate < 0:
            raise AocError(f"a sampling rate must be >= 0, got {rate} for {key}")
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


def parse_rates(items: list[str] | None, flag: str) -> dict[str, float]:
    """``["policy=pi1:4"]`` -> ``{"policy=pi1": 4.0}``."""
    out = {}
    for item in items or []:
        key, sep, rate = item.rpartition(":")
        try:
            value = float(rate)
        except ValueError:
            value = None
        if not sep or "=" not in key or value is None:
            raise AocError(f"{flag} expects TAG=VALUE:RATE (e.g. policy=pi1:4), got {item!r}")
        out[key] = value
    return out


def load_index(corpus, model_id: str | None = None, index_id: str = "default") -> CorpusIndex:
    """Load a built index, refusing one built from another corpus or model."""
    model = _load_model(corpus, model_id)
    out = _index_dir(corpus, model.id, index_id)
    if not (out / "index.json").is_file():
        hint = f"aoc index {corpus.name} --model {model.id}"
        if index_id != "default":
            hint += f" --index-id {index_id} (with its --resample/--subsample)"
        raise AocError(f"no index {index_id!r} for model {model.id!r} of corpus "
                       f"{corpus.name!r}: run `{hint}`")
    meta = json.loads((out / "index.json").read_text())
    if meta.get("corpus_hash") != corpus.hash or meta.get("model_hash") != model.hash:
        raise AocError(f"index {index_id!r} was built from another version of corpus "
                       f"{corpus.name!r} or model {model.id!r}: rebuild it with "
                       f"`aoc index {corpus.name} --model {model.id}`")
    beliefs = np.load(corpus.models_dir / model.id / "beliefs.npy", mmap_mode="r",
                      allow_pickle=False)
    index = BeliefIndex.load(out / "index.faiss", beliefs)
    return CorpusIndex(index_id, model, beliefs, model.values, index, meta)


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
