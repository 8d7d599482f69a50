"""The nearest logged rows by the cells both rows measured: rule 7's distance on a log with
gaps (docs/design.md, "Settings from the log's evidence").

A cell filled at ingest (``--impute hold`` repeats the stay's last measurement, ``median`` the
column's) is not a measurement of the row's own state: over all cells, two rows of one state
differ wherever either held an earlier state's value, and a row's nearest rows are partly
those of the state it left. The distance here reads only what both rows measured:

    D(q, x) = sum_j m_qj m_xj (q_j - x_j)^2 / sum_j m_qj m_xj

(q, x standardised observations, m the measured cells; no cell in common: infinitely far). A
query that measured no cell (every value filled, e.g. held from its history) is read over all
its cells, filled values and all: they are the best it has, and over none every row would be
infinitely far.

FAISS has no such distance, and a brute-force search of every row against every row grows with
the square of the log in memory as well as time. Its numerator, though, is an inner product,

    sum_j m_qj m_xj (q_j - x_j)^2 = <(m_q, -2 m_q q, m_q q^2), (m_x x^2, m_x x, m_x)>,

so an exact FAISS inner-product search (``IndexFlatIP``, BLAS) over 3 d columns finds the
:data:`CANDIDATES` x k rows (at least :data:`LEAST_CANDIDATES`) smallest by the numerator
plus ``cell`` per cell not both measured
(the unmeasured pairs counted at a near neighbour's typical per-cell difference, ``cell``,
estimated once from a sample), and each candidate's distance is then exact: its number of
common cells is a popcount of the two rows' packed masks (``np.bitwise_count``), the
numerator the inner product less ``cell`` times them. The k nearest are the k smallest exact
distances among the candidates. On the cohort test bed (10k stays, noise 0.3) 300
candidates held every one of the exact 100 nearest rows of 2,000 sampled rows, and 2,000
candidates every row of the exact search's 1,000 nearest (the test of this module checks
it against a brute-force search).

Shapes: standard (N, d) float, measured (N, d) bool; ``search(q (S, d), qm (S, d), k)`` ->
(distances (S, k) float64, rows (S, k) int64), nearest first.
"""

from __future__ import annotations

import numpy as np

#: Rows read exactly per query, times the k asked for (the inner-product search's candidates).
CANDIDATES = 4
#: ... and at least this many.
LEAST_CANDIDATES = 400
#: Rows whose near neighbours measure ``cell`` (a seeded sample of the log).
CELL_QUERIES = 200
#: Queries searched at once.
_BLOCK = 1024
#: Cells of one (queries, rows) block of the reference distances that measure ``cell``.
_BRUTE_CELLS = 4_000_000


def pack(measured: np.ndarray) -> np.ndarray:
    """(N, W) uint64: each row's mask (N, d) bool packed 64 cells a word."""
    bits = np.packbits(np.asarray(measured, bool), axis=1, bitorder="little")
    bits = np.pad(bits, ((0, 0), (0, (-bits.shape[1]) % 8)))
    return np.ascontiguousarray(bits).view(np.uint64)


def brute_force(standard: np.ndarray, measured: np.ndarray, q: np.ndarray, qm: np.ndarray
                ) -> np.ndarray:
    """(S, N) the masked distance of every query to every row, in float64 (the reference;
    a few hundred queries at a time)."""
    x, m = np.asarray(standard, np.float64), np.asarray(measured, np.float64)
    return _distances((m, m * x, m * x * x), q, qm)


def _distances(rows: tuple, q: np.ndarray, qm: np.ndarray) -> np.ndarray:
    """:func:`brute_force` from the rows' terms (m, m x, m x^2), each (N, d) float64."""
    m, mx, mxx = rows
    q, qm = np.asarray(q, np.float64), np.asarray(qm, np.float64)
    num = (qm * q * q) @ m.T + qm @ mxx.T - 2.0 * (qm * q) @ mx.T
    den = qm @ m.T
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(den > 0, np.maximum(num, 0.0) / np.maximum(den, 1.0), np.inf)


class MaskedIndex:
    """The logged rows nearest a query by the masked distance (module docstring)."""

    def __init__(self, standard: np.ndarray, measured: np.ndarray,
                 candidates: int | None = None, seed: int = 0):
        import faiss  # lazy: FAISS only where a controller decides with rule 7

        x = np.asarray(standard, np.float64)
        m = np.asarray(measured, bool)
        if m.shape != x.shape:
            raise ValueError(f"measured {m.shape} does not match the observations {x.shape}")
        self.n, self.d = x.shape
        #: a fixed number of candidates (None: CANDIDATES x k, at least LEAST_CANDIDATES)
        self.candidates = candidates
        self.bits = pack(m)
        self.cell = self._cell(x, m, seed)
        mf = m.astype(np.float64)
        base = np.concatenate([mf * x * x, mf * x, mf], axis=1)
        self.index = faiss.IndexFlatIP(base.shape[1])
        self.index.add(np.ascontiguousarray(base, dtype=np.float32))

    @staticmethod
    def _cell(x: np.ndarray, m: np.ndarray, seed: int) -> float:
        """The mean masked distance of a sample's rows to their 10 nearest others: what a
        near neighbour differs by, per cell (it weights the candidates' unmeasured pairs)."""
        n = len(x)
        if n < 2:
            return 0.0
        pick = np.sort(np.random.default_rng(seed).choice(n, min(CELL_QUERIES, n),
                                                          replace=False))
        near = []
        mf = m.astype(np.float64)
        rows = (mf, mf * x, mf * x * x)             # brute_force's row terms, formed once
        block = max(1, min(100, _BRUTE_CELLS // n))   # (block, N) float64 arrays stay small
        for a in range(0, len(pick), block):
            d = _distances(rows, x[pick[a:a + block]], m[pick[a:a + block]])
            d[np.arange(len(d)), pick[a:a + block]] = np.inf      # not the row itself
            k = min(10, n - 1)
            part = np.partition(d, k - 1, axis=1)[:, :k]
            near.append(part[np.isfinite(part)])
        near = np.concatenate(near)
        return float(near.mean()) if len(near) else 0.0

    def search(self, q: np.ndarray, qm: np.ndarray, k: int) -> tuple[np.ndarray, np.ndarray]:
        """((S, k) masked distances, (S, k) rows) of the k nearest rows, nearest first (ties:
        the inner-product order); q (S, d) standardised, qm (S, d) bool its measured cells."""
        q = np.asarray(q, np.float64).reshape(len(q), -1)
        qm = np.asarray(qm, bool).reshape(q.shape)
        qm = qm | ~qm.any(1, keepdims=True)          # no cell measured: read every cell
        c = (max(CANDIDATES * int(k), LEAST_CANDIDATES) if self.candidates is None
             else int(self.candidates))
        c = min(c, self.n)
        k = int(min(k, c))
        qb, qf = pack(qm), qm.astype(np.float64)
        # minus the penalised numerator: the inner product FAISS maximises
        vec = -np.concatenate([qf, -2.0 * qf * q, qf * q * q - self.cell * qf], axis=1)
        dist = np.empty((len(q), k))
        rows = np.empty((len(q), k), np.int64)
        for a in range(0, len(q), _BLOCK):
            ip, cand = self.index.search(np.ascontiguousarray(vec[a:a + _BLOCK], np.float32), c)
            common = np.bitwise_count(self.bits[cand] & qb[a:a + _BLOCK, None, :]).sum(-1)
            num = np.maximum(-ip.astype(np.float64) + self.cell * common, 0.0)
            exact = np.where(common > 0, num / np.maximum(common, 1), np.inf)
            order = np.argsort(exact, axis=1, kind="stable")[:, :k]     # c log c: c is small
            dist[a:a + _BLOCK] = np.take_along_axis(exact, order, 1)
            rows[a:a + _BLOCK] = np.take_along_axis(cand, order, 1)
        return dist, rows
