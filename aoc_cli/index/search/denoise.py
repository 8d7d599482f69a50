"""The rows a neighbourhood is made of on noisy features: the search over the log's raw rows,
each column's spread among near rows, the denoised observation, and the sets themselves, of
varying size (docs/design.md, "Settings from the log's evidence").

A noisy row's nearest rows are chosen partly by its noise. Its **denoised** observation is
the mean of its :data:`SMOOTH` nearest logged rows (each column over those rows that measured
it; where none did, the row's own value): one measurement's noise averaged over twenty. In that
space the rows that share a state gather tightly, and rule 7's set is every logged row within
a radius of the step's denoised observation: :data:`RADIUS` times the log's median squared
distance to a row's 10th nearest (its own local scale, the k-distance rule DBSCAN picks its
radius by), at least :data:`LEAST` rows and at most :data:`CAP`. Where the rows gather, a set
is the gathering's every row; where they do not, the set grows to its cap and rule 7 keeps the
likely action more often (a wide set's bounds are wide).

Each column's unit is its **near-row spread**, sqrt(mean (x_j - x'_j)^2 / 2) over a sample's
rows x and their 10 nearest x' (the cells both measured), the search itself in the previous
round's units (two rounds, the first in the log's sd): of the size of the measurement noise
where near rows share a state (below it, since near rows are chosen near), where the log's sd
reads how far apart the states lie in each column.

FAISS finds the rows (flat L2, exact; :mod:`.masked` over the cells both rows measured on a
log with gaps); a set's rows are kept ragged, as CSR (:class:`Sets`), since a (N, CAP) array
would be 8 GB at 1M rows.

Shapes: observations (N, d) float, measured (N, d) bool or None;
:class:`RowSearch` ``search(obs (S, d), measured (S, d) or None, k)`` -> (distances (S, k),
rows (S, k) int64); :class:`Denoiser` ``(obs (S, d), measured)`` -> (S, d) float64.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from aoc_cli.index.search.masked import MaskedIndex

#: Logged rows whose mean is an observation's denoised position.
SMOOTH = 20
#: A set's radius, in multiples of the log's median squared distance to a 10th nearest row.
RADIUS = 3.0
#: A set's rows: at least, at most.
LEAST, CAP = 30, 1000
#: Rows whose nearest rows measure the spread and the radius (a seeded sample of the log).
SAMPLE = 2000
#: Queries searched at once.
_BLOCK = 4096
#: Set entries worked on at once (:meth:`Sets.blocks`): about 32 MB per (entries,) array.
ENTRIES = 1 << 22


@dataclass(frozen=True)
class Sets:
    """S sets of logged rows, ragged: set i is ``flat[indptr[i]:indptr[i + 1]]``, nearest
    first. ``indptr`` (S + 1,) int64, ``flat`` (nnz,) int32 or int64."""

    indptr: np.ndarray
    flat: np.ndarray

    @classmethod
    def dense(cls, rows: np.ndarray) -> "Sets":
        """The sets of a (S, m) array of rows, each of m rows."""
        rows = np.asarray(rows, np.int64)
        s, m = rows.shape
        return cls(np.arange(s + 1, dtype=np.int64) * m, rows.reshape(-1))

    def array(self) -> np.ndarray:
        """(S, m) the rows, where every set holds m of them (fixed-size sets)."""
        sizes = self.sizes
        if len(sizes) and np.any(sizes != sizes[0]):
            raise ValueError("the sets differ in size: no (S, m) array")
        return self.flat.reshape(len(self), -1)

    def __len__(self) -> int:
        return len(self.indptr) - 1

    def __getitem__(self, i: int) -> np.ndarray:
        return self.flat[self.indptr[i]:self.indptr[i + 1]]

    @property
    def sizes(self) -> np.ndarray:
        """(S,) each set's rows."""
        return np.diff(self.indptr)

    def part(self, a: int, b: int) -> "Sets":
        """Sets a to b (exclusive), their own indptr from 0."""
        lo, hi = self.indptr[a], self.indptr[b]
        return Sets(self.indptr[a:b + 1] - lo, self.flat[lo:hi])

    def blocks(self, entries: int | None = None):
        """(a, b) ranges of consecutive sets holding at most ``entries`` rows in all (one set
        at least): work over the sets' (nnz,) arrays a piece at a time (1,000-row sets of a
        50k-stay cohort hold 4.5e8 entries)."""
        entries = ENTRIES if entries is None else int(entries)
        a, s = 0, len(self)
        while a < s:
            b = int(np.searchsorted(self.indptr, self.indptr[a] + entries, side="right")) - 1
            b = min(max(b, a + 1), s)
            yield a, b
            a = b

    def owner(self) -> np.ndarray:
        """(nnz,) the set each entry of ``flat`` belongs to."""
        return np.repeat(np.arange(len(self), dtype=np.int64), self.sizes)

    def mean(self, values: np.ndarray) -> np.ndarray:
        """(S,) the mean of ``values`` (N,) over each set's rows."""
        total = np.bincount(self.owner(), weights=np.asarray(values)[self.flat],
                            minlength=len(self))
        return total / np.maximum(self.sizes, 1)

    def averaging(self, n: int):
        """(S, n) scipy CSR matrix: row i the mean over set i (a matrix-vector product
        averages a value over every set at once)."""
        from scipy.sparse import csr_matrix
        weight = np.repeat(1.0 / np.maximum(self.sizes, 1), self.sizes)
        small = self.indptr[-1] < np.iinfo(np.int32).max and n < np.iinfo(np.int32).max
        index = np.int32 if small else np.int64        # int32: scipy keeps the rows uncopied
        return csr_matrix((weight, self.flat.astype(index, copy=False),
                           self.indptr.astype(index, copy=False)), shape=(len(self), n))

    @staticmethod
    def join(parts: list["Sets"]) -> "Sets":
        """The sets of ``parts`` one after another."""
        if not parts:
            return Sets(np.zeros(1, np.int64), np.zeros(0, np.int32))
        ends = np.cumsum([0] + [p.indptr[-1] for p in parts[:-1]])
        indptr = np.concatenate([parts[0].indptr[:1]]
                                + [p.indptr[1:] + e for p, e in zip(parts, ends)])
        return Sets(indptr, np.concatenate([p.flat for p in parts]))


class RowSearch:
    """The k logged rows nearest an observation, each column in ``scale`` (about the log's
    mean): FAISS flat L2, or the masked distance over the cells both rows measured where the
    log has filled cells (:class:`~aoc_cli.index.search.masked.MaskedIndex`)."""

    def __init__(self, observations: np.ndarray, measured: np.ndarray | None,
                 scale: np.ndarray, seed: int = 0):
        import faiss  # lazy: FAISS only where a controller decides with rule 7

        obs = np.asarray(observations, np.float64).reshape(len(observations), -1)
        self.n = len(obs)
        self.centre = obs.mean(0) if len(obs) else np.zeros(obs.shape[1])
        self.scale = np.where(np.asarray(scale, np.float64) > 1e-12, scale, 1.0)
        #: the masked index where the log has filled cells, else None
        self.masked = None
        self.index = None
        if measured is not None and not np.all(measured):
            self.masked = MaskedIndex(self.standard(obs), measured, seed=seed)
        else:
            self.index = faiss.IndexFlatL2(obs.shape[1])
            self.index.add(self.standard(obs))

    @classmethod
    def of_standard(cls, standard: np.ndarray, centre: np.ndarray, scale: np.ndarray
                    ) -> "RowSearch":
        """The flat search over rows already standardised, (N, d) float32 (as
        :meth:`standard` made them), ``centre`` and ``scale`` (d,) how."""
        import faiss  # lazy: FAISS only where a controller decides with rule 7

        self = cls.__new__(cls)
        base = np.ascontiguousarray(standard, np.float32)
        self.n, self.masked = len(base), None
        self.centre = np.asarray(centre, np.float64)
        self.scale = np.asarray(scale, np.float64)
        self.index = faiss.IndexFlatL2(base.shape[1])
        self.index.add(base)
        return self

    def standard(self, obs: np.ndarray) -> np.ndarray:
        """(S, d) float32: observations less the log's mean, over ``scale``."""
        return np.ascontiguousarray((np.asarray(obs, np.float64) - self.centre) / self.scale,
                                    dtype=np.float32)

    def search(self, obs: np.ndarray, measured: np.ndarray | None, k: int
               ) -> tuple[np.ndarray, np.ndarray]:
        """((S, k) squared distances, (S, k) rows) of the k nearest rows, nearest first;
        ``measured`` (S, d) bool the query's measured cells (None: all; read on a log with
        gaps)."""
        obs = np.asarray(obs, np.float64).reshape(len(obs), -1)
        k = int(min(k, self.n))
        dist, rows = np.empty((len(obs), k)), np.empty((len(obs), k), np.int64)
        qm = None
        if self.masked is not None:
            qm = (np.ones(obs.shape, bool) if measured is None
                  else np.asarray(measured, bool).reshape(obs.shape))
        for a in range(0, len(obs), _BLOCK):
            q = self.standard(obs[a:a + _BLOCK])
            if self.masked is not None:
                d, r = self.masked.search(q, qm[a:a + _BLOCK], k)
            else:
                d, r = self.index.search(q, k)
            dist[a:a + _BLOCK], rows[a:a + _BLOCK] = d, r
        return dist, rows


def near_row_spread(observations: np.ndarray, measured: np.ndarray | None = None,
                    near: int = 10, rounds: int = 2, seed: int = 0) -> np.ndarray:
    """(d,) each column's spread among near rows (module docstring); observations (N, d),
    measured (N, d) bool or None. A column that no two near rows both measured keeps its sd;
    none falls below a twentieth of it."""
    obs = np.asarray(observations, np.float64).reshape(len(observations), -1)
    n = len(obs)
    m = np.ones(obs.shape, bool) if measured is None else np.asarray(measured, bool)
    sd = obs.std(0) if n else np.ones(obs.shape[1])
    sd = np.where(sd > 1e-12, sd, 1.0)
    if n < 2:
        return sd
    pick = np.sort(np.random.default_rng(seed).choice(n, size=min(SAMPLE, n), replace=False))
    scale = sd
    for _ in range(rounds):
        search = RowSearch(obs, measured, scale, seed=seed)
        rows = search.search(obs[pick], None if measured is None else m[pick], near + 1)[1]
        diff = obs[rows] - obs[pick][:, None]                           # (Q, near + 1, d)
        both = m[rows] & m[pick][:, None] & np.any(diff != 0, axis=2, keepdims=True)
        count = both.sum((0, 1))
        var = np.divide((diff ** 2 * both).sum((0, 1)), count, out=sd ** 2 * 2,
                        where=count > 0)
        scale = np.maximum(np.sqrt(var / 2.0), 0.05 * sd)
    return scale


class Denoiser:
    """An observation's denoised position: the mean of its ``smooth`` nearest logged rows
    (module docstring)."""

    def __init__(self, observations: np.ndarray, measured: np.ndarray | None,
                 scale: np.ndarray, smooth: int = SMOOTH, seed: int = 0):
        self.x = np.asarray(observations, np.float64).reshape(len(observations), -1)
        self.m = None if measured is None else np.asarray(measured, bool)
        self.smooth = int(smooth)
        self.search = RowSearch(self.x, measured, scale, seed=seed)

    def __call__(self, obs: np.ndarray, measured: np.ndarray | None = None) -> np.ndarray:
        """(S, d) the denoised observations (S, d), ``measured`` (S, d) their measured
        cells (None: all)."""
        obs = np.asarray(obs, np.float64).reshape(len(obs), -1)
        out = np.empty(obs.shape)
        for a in range(0, len(obs), _BLOCK):
            rows = self.search.search(obs[a:a + _BLOCK],
                                      None if measured is None else measured[a:a + _BLOCK],
                                      self.smooth)[1]                   # (S, smooth)
            if self.m is None:
                out[a:a + _BLOCK] = self.x[rows].mean(1)
                continue
            w = self.m[rows]                                            # (S, smooth, d)
            held = w.sum(1)
            total = np.where(w, self.x[rows], 0.0).sum(1)
            out[a:a + _BLOCK] = np.where(held > 0, total / np.maximum(held, 1),
                                         obs[a:a + _BLOCK])
        return out
