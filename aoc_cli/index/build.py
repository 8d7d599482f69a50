"""Build and load a corpus index: the beliefs of every row of a corpus under a belief model,
and the index the controller searches (the stage between decompose and control).

Layout under ``<corpus>/models/<model>/``::

    beliefs.npy                 (N, d_b) float32, memory-mappable, the belief of every row
    beliefs.json                the model and corpus hashes the beliefs were computed from
    index/<index_id>/index.faiss    the FAISS index (+ .json, its config)
    index/<index_id>/index.faiss.rows.npy  (M,) int64: entry -> corpus row (derived indexes)
    index/<index_id>/index.json     what it was built from (corpus, model hashes), kind, size

The ``default`` index holds every row once. Derived indexes re-sample or sub-sample rows by
tag (the paper's adaptivity experiment) with no retraining: an episode rate of 4 for
``policy=pi1`` repeats pi1's rows four times, 0.5 keeps a random half of its episodes
(:func:`aoc_cli.rows.episode_multiplicity`).
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from aoc_cli import belief
from aoc_cli.decompose.k_rule import index_k
from aoc_cli.errors import AocError, BadSetting, IndexMissing, IndexStale, call, param
from aoc_cli.index.corpus import CorpusIndex
from aoc_cli.index.search import BeliefIndex
from aoc_cli.index.search.strata import NEAREST, PER_ACTION
from aoc_cli.progress import Progress
from aoc_cli.rows import episode_multiplicity
from aoc_cli.store import (DEFAULT_INDEX, Corpus, atomic_dir, derived, index_dir, model_dir,
                           writing_model)

#: Rows sampled to measure the corpus's typical residual (leave-those-rows-out).
TYPICAL_SAMPLE = 500


def model_k(corpus: Corpus, model, candidates: str = "auto") -> tuple[int, str]:
    """The default k (neighbours per query) of ``model`` on ``corpus`` and where it comes from:
    the k saved with the model (``metrics.controller.k``: the k rule's when ``aoc train``
    ran it, or the ``--k`` it was given), else the k rule,
    :func:`aoc_cli.decompose.k_rule.index_k` (docs/design.md, "Candidates of every action"),
    once ``candidates`` is checked: "auto" (the model's, else that rule), "nearest" (the
    paper's k) or "per_action" (discrete actions only): a ``candidates`` given takes its
    rule's k."""
    if candidates not in ("auto", NEAREST, PER_ACTION):
        raise BadSetting("neighbours", candidates,
                         f"unknown {param('neighbours')} {candidates!r}: use auto, {NEAREST} or "
                         f"{PER_ACTION}")
    if candidates == PER_ACTION and not (corpus.discrete and corpus.n_rows > 0):
        raise BadSetting("neighbours", candidates,
                         f"{param('neighbours', PER_ACTION)} needs discrete actions; corpus "
                         f"{corpus.name!r} has continuous ones")
    imitation = model.mode == "imitation" and bool(corpus.discrete) and corpus.n_rows > 0
    k, how = index_k(model.d_b, corpus, imitation, candidates)
    meta = getattr(model, "meta", None) or {}  # a model-free session has none
    saved = ((meta.get("metrics") or {}).get("controller") or {}).get("k")
    if candidates == "auto" and saved is not None:  # the k saved with the model
        k = int(saved)
    return k, how


def build_index(corpus: Corpus, model_id: str | None = None, kind: str = "auto",
                index_id: str = DEFAULT_INDEX, episode_rates: dict | None = None,
                seed: int = 0, progress: Progress | None = None, *,
                resample: dict | None = None, subsample: dict | None = None,
                candidates: str = "auto", **params) -> CorpusIndex:
    """Compute (or reuse) the beliefs of every row and build an index over them; ``progress``:
    the rows whose beliefs are computed (:mod:`aoc_cli.progress`).

    ``episode_rates`` ``{"TAG=VALUE": rate}`` derive an index that keeps or repeats whole
    episodes (:func:`aoc_cli.rows.episode_multiplicity`); ``resample`` and ``subsample``, the
    older names, are merged into them. ``candidates``: step 1's, "auto", "nearest" or
    "per_action" (:func:`model_k`), recorded with its k in ``index.json``.

    Built in a temporary folder beside the index folder (new beliefs staged in it) and
    swapped in only when everything succeeded (:mod:`aoc_cli.store.derived`)."""
    from aoc_cli.belief.stream import write_row_beliefs  # lazy: torch (a model is loaded)

    episode_rates = {**(resample or {}), **(subsample or {}), **(episode_rates or {})}
    model = belief.load_model(corpus, model_id)  # torch, loaded here (the package is lazy)
    k, how = model_k(corpus, model, candidates)
    if episode_rates and index_id == DEFAULT_INDEX:
        raise AocError("index_id must name a new index for a re-sampled or sub-sampled one "
                       "(the default index holds every row once)", "index_id")
    folder = model_dir(corpus.path, model.id)
    out = index_dir(corpus.path, model.id, index_id)
    todo = f"retrain it: `{call('train', corpus.name, model=model.id, overwrite=True)}`"
    fresh = derived.beliefs_fresh(folder, model.hash)
    with writing_model(corpus.path, model.id), atomic_dir(out) as tmp:
        # the columns the beliefs read, hashed on the way (with reused beliefs a pass of its
        # own, small beside building the index: an index of damaged data is never built)
        corpus.verify_content()
        staged = None
        if fresh:
            beliefs = derived.open_beliefs(folder, f"beliefs of model {model.id!r}", todo)
        else:
            if progress is not None:
                progress(0, corpus.n_rows, "beliefs of every row")
            # chunk by chunk into a memory-mapped file: (N, d_b) is never held in memory
            staged = write_row_beliefs(model, corpus, Path(tmp) / derived.BELIEFS,
                                       progress=progress)
            beliefs = np.load(staged, mmap_mode="r", allow_pickle=False)
            derived.check_finite(beliefs, f"model {model.id!r} of corpus {corpus.name!r}",
                                 todo)
        start = time.perf_counter()
        index = BeliefIndex.build(beliefs, kind=kind, seed=seed, **params)
        if episode_rates:
            index = index.resample(episode_multiplicity(corpus, episode_rates, seed))
        seconds = time.perf_counter() - start
        index.save(tmp / "index.faiss")
        meta = {
            "index_id": index_id, "model": model.id, "model_hash": model.hash,
            "corpus": corpus.name, "corpus_hash": corpus.hash, "kind": index.kind,
            "rows": int(index.size), "belief_dim": int(beliefs.shape[1]),
            "episode_rates": episode_rates, "seed": seed,
            "build_seconds": seconds, "built": time.strftime("%Y-%m-%dT%H:%M:%S%z"),
        }
        meta["k"], meta["candidates"] = k, how
        ci = CorpusIndex(index_id, model, beliefs, model.values, index, meta,
                         _strata(corpus, meta))
        meta["typical_residual"] = typical_residual(ci, seed)
        derived.write_index_meta(tmp, meta)
        if staged is not None:  # everything built: the beliefs go in first, then the index
            derived.commit_beliefs(staged, folder, {
                "model_hash": model.hash, "corpus_hash": corpus.hash,
                "shape": list(beliefs.shape)})
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
            "p99": float(np.quantile(r, 0.99)), "sample": int(len(sample)), "k": ci.k}


def load_index(corpus: Corpus, model_id: str | None = None,
               index_id: str = DEFAULT_INDEX) -> CorpusIndex:
    """Load a built index, refusing one built from another corpus or model, or damaged."""
    model = belief.load_model(corpus, model_id)  # torch, loaded here (the package is lazy)
    out = index_dir(corpus.path, model.id, index_id)
    hint = call("build_index", corpus.name, model=model.id)
    if index_id != DEFAULT_INDEX:
        hint = (call("build_index", corpus.name, model=model.id, index_id=index_id)
                + f" (with its {param('episode_rates')})")
    if not (out / "index.json").is_file():
        raise IndexMissing(corpus.name, model.id, index_id)
    what = f"index {index_id!r} of model {model.id!r} of corpus {corpus.name!r} is damaged"
    todo = f"rebuild it with `{hint}`"
    meta = derived.open_index_meta(out, what, todo)
    if meta.get("corpus_hash") != corpus.hash or meta.get("model_hash") != model.hash:
        raise IndexStale(corpus.name, model.id, index_id,
                         {"corpus": meta.get("corpus_hash"), "model": meta.get("model_hash")},
                         {"corpus": corpus.hash, "model": model.hash})
    beliefs = derived.open_beliefs(model_dir(corpus.path, model.id), what, todo)
    index = load_faiss(out / "index.faiss", beliefs, what, todo)
    return CorpusIndex(index_id, model, beliefs, model.values, index, meta, _strata(corpus, meta))


def load_faiss(path: Path, beliefs, what: str, todo: str):
    """``BeliefIndex.load`` with FAISS's errors (a damaged file) as one AocError."""
    try:
        return BeliefIndex.load(path, beliefs)
    except AocError:
        raise
    except Exception as err:  # FAISS raises RuntimeError; numpy ValueError on the row map
        first = str(err).strip().splitlines()[0][:120] if str(err).strip() else ""
        raise AocError(f"{what}: reading {path} failed ({type(err).__name__}: {first}); "
                       f"{todo}") from None


def _strata(corpus: Corpus, meta: dict) -> np.ndarray | None:
    """(N,) the rows' actions when the index takes its candidates per action, else None."""
    if meta.get("candidates") != PER_ACTION:
        return None
    return np.asarray(corpus.actions, dtype=np.int64)
