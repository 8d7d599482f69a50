"""The decomposition of query beliefs against the corpus, batched, in the paper's four steps.

For each query belief y (one per candidate action of a control step):

1. neighbours      N_k(y): the k nearest corpus beliefs B (k, d_b), from the index;
2. residual        r(y) = min_{w in simplex} ||B^T w - y||,  y* = B^T w  (exact; minnorm.py);
3. minimal subset  at most d_b + 1 affinely independent rows whose hull contains y*, of the
                   smallest volume found (hull.py), with weights w >= 0, sum w = 1, B_S^T w = y*;
4. value           v_hat(y) = sum_c w_c v_c.

(Definitions "Belief Corpus Residual" and "Minimal Hull and Minimal Corpus Subset" of the AOC
paper; docs/design.md "The method, precisely".)
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from aoc_cli.decompose.hull import minimal_subset
from aoc_cli.decompose.k_rule import default_k
from aoc_cli.decompose.minnorm import min_norm_point
from aoc_cli.decompose.reference import caratheodory, lifted_nnls_weights, reference_weights
from aoc_cli.errors import AocError
from aoc_cli.index.search import BeliefIndex
from aoc_cli.index.search.exact import nearest_rows
from aoc_cli.index.search.faiss_kinds import check_queries
from aoc_cli.settings import Settings, setting
from aoc_cli.threads import single_threaded_blas


@dataclass(frozen=True)
class DecomposeConfig(Settings):
    """How a query belief is decomposed over the corpus (paper defaults).

    k: neighbours per query; None means the paper's k = 2 (d_b + 1) (appendix "Finding the
        Minimal Convex Hull Efficiently"), clipped to the corpus size.
    qp_tol: relative optimality tolerance of step 2, on the Frank-Wolfe gap
        <x, x> - min_c <b_c - y, x>  with x = y* - y: at most qp_tol ||x||^2 plus 1e-15 of the
        squared neighbourhood radius (minnorm.py), so ||x|| - r <= qp_tol ||x|| + 1e-15 / ||x||.
    lp_start: step 3 starts from the lifted-LP vertex, the Delaunay simplex containing y*
        (min sum w_c ||b_c - y*||^2 s.t. B^T w = y*, w in simplex).
    exchange_budget: at most this many volume-reducing vertex exchanges in step 3.
    reference: solve step 2 with the reference QP (piqp) instead of the batched solver.
    """

    label = "decomposition"

    k: int | None = setting(None, bounds=">= 1", none="2 (d_b + 1), at most the corpus's rows",
                            help="Nearest corpus beliefs per query.")
    qp_tol: float = setting(1e-10, bounds=">= 0",
                            help="Relative optimality tolerance of step 2's QP.")
    lp_start: bool = setting(True, help="Step 3 starts from the lifted-LP vertex.")
    exchange_budget: int = setting(64, bounds=">= 0",
                                   help="Volume-reducing vertex exchanges of step 3, at most.")
    reference: bool = setting(False, help="Solve step 2 with the reference QP (piqp).")


#: The paper's settings (a frozen config: shared by every call that gives none).
_DEFAULT = DecomposeConfig()


@dataclass
class Decomposition:
    """The decomposition of Q query beliefs; m = min(d_b + 1, k) columns per query.

    rows: (Q, m) int64 corpus rows of the minimal corpus subset, by decreasing weight, -1 padded.
    weights: (Q, m) float64, >= 0, summing to 1, 0 where padded.
    residual: (Q,) float64 corpus residual r = ||y* - y|| (0 inside the neighbours' hull).
    projection: (Q, d_b) y*, the nearest point of the neighbours' hull.
    distance: (Q, m) ||b_c - y|| of each supporting row, nan where padded.
    value: (Q,) sum_c w_c v_c when values were given, else None.
    neighbours: (Q, k) corpus rows searched (step 1), -1 padded.
    fallbacks: queries whose step 2 went to the reference QP. pivots: step-3 exchange rounds.
    """

    rows: np.ndarray
    weights: np.ndarray
    residual: np.ndarray
    projection: np.ndarray
    distance: np.ndarray
    value: np.ndarray | None
    neighbours: np.ndarray
    fallbacks: int = 0
    pivots: int = 0


#: A full minimal subset (d + 1 rows) sets the residual to 0 only when step 2's residual is at
#: most this share of the neighbourhood's radius (the compiled loop certifies in-hull points to
#: minnorm.ABS_TOL = 3e-8 of it).
FULL_TOL = 1e-6


def decompose(
    beliefs: np.ndarray,
    queries: np.ndarray,
    k: int | None = None,
    values: np.ndarray | None = None,
    index: BeliefIndex | None = None,
    reference: bool = False,
    selection=None,
    config: DecomposeConfig | None = None,
) -> Decomposition:
    """Decompose each query belief over its nearest corpus beliefs (steps 1-4 above).

    beliefs: (N, d_b) corpus beliefs; queries: (Q, d_b); k: neighbours (default 2(d_b + 1));
    values: (N,) row values v; index: a BeliefIndex over `beliefs` (default: exact search);
    reference: step 2 by the reference QP; selection: restrict to a row mask / row ids.

    Without ``index`` step 1 is an exact search that builds nothing (aoc_cli/index/search/exact.py:
    one pass over the beliefs, O(N d_b) a call), with the same neighbours as an exact ("flat")
    index. A caller that decomposes many batches against the same corpus should keep a
    ``BeliefIndex.build(beliefs)`` and pass it as ``index``: its cell structure, built on its
    first batch, skips most rows, and an approximate kind ("ivf", "hnsw") reads a fraction of
    them; the float32 beliefs it keeps are also reused (a float64 ``beliefs`` array is
    otherwise converted on every call). docs/notes/benchmarks-rounds.md "decompose without an index".
    """
    config = config or _DEFAULT
    beliefs, Y, values = _check_inputs(beliefs, queries, values)
    n_rows, d = beliefs.shape
    k = config.k if k is None else k
    k = default_k(d) if k is None else int(k)
    if k < 1:
        raise AocError(f"k must be at least 1 (got {k}); use the default 2(d+1) or a positive number")
    k = min(k, n_rows)
    if index is not None and (index.n_rows != n_rows or index.dim != d):
        raise AocError(
            f"the index covers ({index.n_rows}, {index.dim}) beliefs, not ({n_rows}, {d}); rebuild the index"
        )
    with single_threaded_blas():
        return _decompose(beliefs, Y, k, values, index, reference or config.reference, selection, config)


def _decompose(beliefs, Y, k, values, index, reference, selection, config) -> Decomposition:
    n_q, d = Y.shape
    if n_q == 0:
        m = min(d + 1, k)
        empty = np.zeros((0, m))
        return Decomposition(
            np.zeros((0, m), np.int64), empty, np.zeros(0), np.zeros((0, d)), empty,
            None if values is None else np.zeros(0), np.zeros((0, k), np.int64),
        )

    # 1. neighbours: the k nearest corpus beliefs of every query (exact, nothing built, when
    # there is no index)
    if index is None:
        _, neighbours = nearest_rows(beliefs, Y, k, selection)
    else:
        _, neighbours = index.search(Y, k, selection)
    valid = neighbours >= 0
    # float32 beliefs (as an index stores them) are read from the index's own rows where it
    # keeps them in memory: the same values, and a memory-mapped array's pages stay out
    gather = getattr(index, "row_beliefs", None) if beliefs.dtype == np.float32 else None
    B32 = gather(np.maximum(neighbours, 0)) if gather is not None else None
    if B32 is None:
        B32 = np.take(beliefs, np.maximum(neighbours, 0), axis=0)
    B = np.asarray(B32, dtype=np.float64).reshape(neighbours.shape + (beliefs.shape[1],))
    P = B - Y[:, None, :]  # neighbours relative to the query, p_c = b_c - y

    # 2. corpus residual and projection: min_{w in simplex} ||B^T w - y||, exactly
    weights, failed = _residual_weights(B, Y, P, valid, reference, config.qp_tol)
    offset = np.einsum("qk,qkd->qd", weights, P)  # y* - y
    residual = np.sqrt((offset**2).sum(1))

    # 3. minimal corpus subset: exchange vertices while the hull shrinks and still holds y*
    weights, support, pivots = minimal_subset(
        P, valid, weights, offset, lp_start=config.lp_start, budget=config.exchange_budget
    )
    # d + 1 affinely independent points hold y* in their simplex's interior, so y* = y and r = 0
    # when step 2 is exact; only where step 2's residual is already at its certified precision
    # (a fallback QP stopped inside the hull would otherwise zero an outside query's residual)
    sq = np.einsum("qkd,qkd->qk", P, P)  # (Q, k) squared distances ||b_c - y||^2
    radius = np.sqrt(np.where(valid, sq, 0.0).max(1))
    full = (support.sum(1) == d + 1) & (residual <= FULL_TOL * radius)
    residual[full] = 0.0
    offset[full] = 0.0

    rows, w_out, dist, used = _subset_columns(weights, neighbours, sq, min(d + 1, k))

    # 4. value estimate: v_hat = sum_c w_c v_c over the subset
    # as v_0 + sum_c w_c (v_c - v_0), v_0 the heaviest row's value: equal row values give that
    # value exactly, so candidates whose rows share a value tie exactly (the controller then
    # breaks the tie by residual, not by the rounding of the weighted sum)
    value = None
    if values is not None:
        v = np.where(used, values[np.maximum(rows, 0)], 0.0)
        value = v[:, 0] + (w_out * (v - v[:, :1])).sum(1)
    return Decomposition(
        rows=rows.astype(np.int64),
        weights=w_out,
        residual=residual,
        projection=Y + offset,
        distance=dist,
        value=value,
        neighbours=neighbours.astype(np.int64),
        fallbacks=int(len(failed)) if not reference else 0,
        pivots=pivots,
    )


def _residual_weights(B: np.ndarray, Y: np.ndarray, P: np.ndarray, valid: np.ndarray,
                      reference: bool, qp_tol: float) -> tuple[np.ndarray, np.ndarray]:
    """Step 2: (Q, k) simplex weights of y* over the neighbours B (Q, k, d) of queries Y
    (Q, d), P = B - y, and the queries that went to the reference QP. The batched solver
    first; a query it cannot certify (or every query, with ``reference``) is solved by the
    reference QP (piqp, else an active-set solver), and the smaller residual is kept."""
    if reference:
        weights, failed = np.zeros(valid.shape), np.arange(Y.shape[0])
    else:
        solved = min_norm_point(P, valid, tol=qp_tol)
        weights, failed = solved.weights, np.flatnonzero(~solved.ok)
    for q in failed:
        c = np.flatnonzero(valid[q])
        try:
            w = reference_weights(B[q, c], Y[q])
        except RuntimeError:  # piqp stalled at every tolerance: an active-set solver instead
            w = lifted_nnls_weights(B[q, c], Y[q])
        w = caratheodory(B[q, c], w)
        # keep whichever of the two answers has the smaller residual: near a zero residual
        # the batched solver's certificate can fail while its point is the better one
        if reference or np.sum((w @ P[q, c]) ** 2) <= np.sum((weights[q, c] @ P[q, c]) ** 2):
            weights[q] = 0.0
            weights[q, c] = w
    return weights, failed


def _subset_columns(weights: np.ndarray, neighbours: np.ndarray, sq: np.ndarray, m: int):
    """The minimal subset as m columns by decreasing weight: rows (Q, m) (-1 padded),
    weights (Q, m) normalised to sum 1, distances ||b_c - y|| (Q, m) (nan padded), and the
    (Q, m) bool of the columns used; sq (Q, k): the squared distances of all neighbours."""
    order = np.argsort(-weights, axis=1, kind="stable")[:, :m]
    w_out = np.take_along_axis(weights, order, axis=1)
    used = w_out > 0
    rows = np.where(used, np.take_along_axis(neighbours, order, axis=1), -1)
    w_out = np.where(used, w_out, 0.0)
    w_out /= w_out.sum(1, keepdims=True)
    dist = np.sqrt(np.take_along_axis(sq, order, axis=1))
    dist = np.where(used, dist, np.nan)
    return rows, w_out, dist, used


def _check_inputs(beliefs, queries, values):
    beliefs = np.asarray(beliefs)
    if beliefs.ndim != 2 or beliefs.shape[0] == 0:
        raise AocError(f"the corpus beliefs must be a non-empty (N, d) array; got shape {beliefs.shape}")
    Y = check_queries(queries, beliefs.shape[1])
    if values is not None:
        values = np.asarray(values, dtype=np.float64)
        if values.shape != (beliefs.shape[0],):
            raise AocError(f"values need one entry per corpus row ({beliefs.shape[0]}); got shape {values.shape}")
    return beliefs, Y, values
