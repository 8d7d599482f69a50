"""What rule 7's search over the measured cells costs beside the plain one, on the cohort test
bed's log (docs/benchmarks/control.md, "Rule 7's neighbourhood search").

    OMP_NUM_THREADS=1 .venv/bin/python benchmarks/perf/masked_search.py [--stays 10000]
        [--noise 0.3] [--queries 4096] [--repeats 5] [-f json]

The cohort table of ``--stays`` stays (``cohort_table``, seed 0: its rows with the gaps held
forward, as ``aoc ingest --impute hold`` stores them), standardised by the log's spread. Cases,
interleaved round by round, each the 100 nearest logged rows of ``--queries`` of the log's own
rows (with their own measured cells):

* ``plain``: FAISS flat L2 over every cell (rule 7 on a log without gaps);
* ``masked``: :class:`aoc_cli.index.search.masked.MaskedIndex` (the inner-product candidates,
  then exact distances), the index built once;
* ``brute``: the same distances by dense float64 matrix products over every logged row
  (``masked.brute_force``), the exact reference, on a quarter of the queries.

One row per case: the median wall seconds, queries per second, and for ``masked`` its recall
of the exact 100 nearest (the share of ``brute``'s rows it returns) and the index's build
time; the ratio of each to ``plain`` is the median of the rounds' own ratios.
"""

from __future__ import annotations

import _harness as h

h.omp_threads(1)

import numpy as np  # noqa: E402  (after the thread count is set)

import aoc_cli.envs.icu_cohort as cohort  # noqa: E402
from aoc_cli.index.search.masked import MaskedIndex, brute_force  # noqa: E402

NEAREST = 100


def main() -> None:
    ap = h.parser(__doc__, repeats=5)
    ap.add_argument("--stays", type=int, default=10_000)
    ap.add_argument("--noise", type=float, default=0.3)
    ap.add_argument("--queries", type=int, default=4096)
    args = ap.parse_args()
    import faiss

    cols = cohort.cohort_table(args.stays, args.noise, seed=0)
    ids = cols["id"]
    starts = np.r_[0, np.nonzero(np.diff(ids))[0] + 1, len(ids)]
    raw = np.stack([cols[c] for c in cohort.OBS_COLUMNS], 1).astype(np.float64)
    measured = ~np.isnan(raw)
    x = cohort.hold_forward(raw, starts)
    x = (x - x.mean(0)) / x.std(0)
    pick = np.sort(np.random.default_rng(0).choice(len(x), args.queries, replace=False))
    q, qm = x[pick], measured[pick]
    quarter = max(1, len(pick) // 4)

    flat = faiss.IndexFlatL2(x.shape[1])
    flat.add(np.ascontiguousarray(x, np.float32))
    index, build, _ = h.timed(lambda: MaskedIndex(x, measured))
    cases = {
        "plain": lambda i: flat.search(np.ascontiguousarray(q, np.float32), NEAREST)[1],
        "masked": lambda i: index.search(q, qm, NEAREST)[1],
        "brute": lambda i: np.argsort(brute_force(x, measured, q[:quarter], qm[:quarter]),
                                      axis=1)[:, :NEAREST],
    }
    runs = h.interleave(cases, args.repeats)
    exact, got = runs["brute"].out, runs["masked"].out[:quarter]
    recall = float(np.mean([np.isin(exact[i], got[i]).mean() for i in range(quarter)]))
    rows = [
        h.row("plain", len(q), runs["plain"], "queries"),
        h.row("masked", len(q), runs["masked"], "queries", recall=round(recall, 4),
              build_s=round(build, 2), vs_plain=round(h.paired(runs["plain"],
                                                                runs["masked"]), 2)),
        h.row("brute", quarter, runs["brute"], "queries"),
    ]
    h.emit(rows, args.format)


if __name__ == "__main__":
    main()
