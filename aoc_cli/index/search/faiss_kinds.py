"""The FAISS structures behind a BeliefIndex: one per kind (flat, HNSW, IVF), a zero-copy view of
a flat index's stored vectors, and the checks of the belief and query arrays given to it.

Shapes: beliefs (N, d) float32, C-contiguous (what FAISS reads without a copy); queries (Q, d).
"""

from __future__ import annotations

import faiss
import numpy as np

from aoc_cli.errors import AocError
from aoc_cli.index.search.config import IndexConfig

#: Rows added to a FAISS index at once.
ADD_CHUNK = 1 << 20


def new_faiss(kind: str, train: np.ndarray, config: IndexConfig) -> faiss.Index:
    d = train.shape[1]
    if kind == "flat":
        return faiss.IndexFlatL2(d)
    if kind == "hnsw":
        index = faiss.IndexHNSWFlat(d, config.hnsw_m)
        index.hnsw.efConstruction = config.hnsw_ef_construction
        index.hnsw.efSearch = config.hnsw_ef_search
        return index
    if kind == "ivf":
        nlist = config.nlist(train.shape[0])
        index = faiss.IndexIVFFlat(faiss.IndexFlatL2(d), d, nlist)
        index.cp.seed = config.seed
        n_train = min(train.shape[0], max(config.ivf_train_max, 40 * nlist))
        rng = np.random.default_rng(config.seed)
        pick = np.sort(rng.choice(train.shape[0], size=n_train, replace=False))
        index.train(np.ascontiguousarray(train[pick]))
        index.nprobe = config.ivf_nprobe
        return index
    raise AocError(f"unknown index kind {kind!r}; use flat, hnsw, ivf or auto")


def storage_view(index: faiss.Index, kind: str) -> np.ndarray | None:
    """Zero-copy (ntotal, d) view of the vectors of a flat or HNSW-flat index."""
    flat = None
    if isinstance(index, faiss.IndexFlat):
        flat = index
    elif isinstance(index, faiss.IndexHNSW):
        storage = faiss.downcast_index(index.storage)
        flat = storage if isinstance(storage, faiss.IndexFlat) else None
    if flat is None or flat.ntotal == 0:
        return None
    return faiss.rev_swig_ptr(flat.get_xb(), flat.ntotal * flat.d).reshape(flat.ntotal, flat.d)


def kind_of(index: faiss.Index) -> str:
    if isinstance(index, faiss.IndexHNSW):
        return "hnsw"
    if isinstance(index, faiss.IndexIVF):
        return "ivf"
    return "flat"


def as_beliefs(beliefs) -> np.ndarray:
    arr = np.asarray(beliefs)
    if arr.ndim != 2:
        raise AocError(f"beliefs must be an (N, d) array; got shape {arr.shape}")
    if arr.dtype != np.float32 or not arr.flags.c_contiguous:
        arr = np.ascontiguousarray(arr, dtype=np.float32)
    return arr


def check_queries(queries, dim: int) -> np.ndarray:
    """Query beliefs as a finite (Q, dim) float64 array (one (dim,) query becomes (1, dim));
    anything else is an AocError. The index and the decomposition engine both check with it."""
    Y = np.asarray(queries, dtype=np.float64)
    if Y.ndim == 1 and Y.shape[0] == dim:
        Y = Y[None, :]
    if Y.ndim != 2 or Y.shape[1] != dim:
        raise AocError(f"queries must have shape (Q, {dim}) to match the corpus beliefs; got "
                       f"{np.shape(queries)}")
    if not np.isfinite(Y).all():
        raise AocError("queries contain NaN or infinite values; check the belief model's inputs")
    return Y


def as_queries(queries, dim: int) -> np.ndarray:
    return np.ascontiguousarray(check_queries(queries, dim), dtype=np.float32)
