"""The batch search: the nearest rows of many scattered queries at once over an IVF-Flat
structure built for the run (``aoc evaluate`` on a large corpus,
:func:`aoc_cli.evaluation.context.search_structure`). Arrays only, like the rest of
:mod:`aoc_cli.index.search`."""

from __future__ import annotations

import numpy as np

#: IVF lists visited per query.
IVF_NPROBE = 16


class BatchSearch:
    """Nearest rows of many scattered queries at once: a FAISS IVF-Flat structure over
    (N, d) vectors (nlist about sqrt(N), a power of two; ``nprobe`` lists visited), one
    threaded-free ``search`` per batch. Distances are exact for the rows found; a true
    neighbour is missed only when it lies outside the visited lists. Quacks like a
    BeliefIndex for :func:`aoc_cli.decompose.decompose`."""

    def __init__(self, vectors: np.ndarray, nprobe: int = IVF_NPROBE, seed: int = 0):
        import faiss

        x = np.ascontiguousarray(vectors, dtype=np.float32)
        self.n_rows, self.dim = x.shape
        self.nlist = int(min(4096, 2 ** int(np.floor(np.log2(max(np.sqrt(self.n_rows), 1))))))
        quantiser = faiss.IndexFlatL2(self.dim)
        self.index = faiss.IndexIVFFlat(quantiser, self.dim, self.nlist)
        self.index.cp.seed = int(seed)
        self.index.train(x)
        self.index.add(x)
        self.index.nprobe = int(nprobe)
        self._quantiser = quantiser

    def describe(self) -> str:
        return f"ivf (nlist {self.nlist}, nprobe {self.index.nprobe})"

    def search(self, queries, k, selection=None):
        """The k nearest rows found, within ``selection`` (an (N,) bool mask) when given: the
        restricted search visits ``nprobe / (the selected share)`` lists (at most all), about
        as many selected rows as the unrestricted search visits rows."""
        params = None
        if selection is not None:
            import faiss

            mask = np.ascontiguousarray(selection, dtype=bool)
            bits = np.packbits(mask, bitorder="little")
            share = max(float(mask.mean()), 1e-12)
            params = faiss.SearchParametersIVF(
                sel=faiss.IDSelectorBitmap(mask.size, faiss.swig_ptr(bits)),
                nprobe=int(min(self.nlist, np.ceil(self.index.nprobe / share))))
        dist, rows = self.index.search(np.ascontiguousarray(queries, dtype=np.float32), int(k),
                                       params=params)
        dist = np.where(rows >= 0, np.sqrt(np.maximum(dist, 0.0)), np.inf)
        return dist.astype(np.float64), rows.astype(np.int64)
