"""Benchmark: neighbours + decomposition per control step, against the paper's procedure.

For each corpus size: generate structured beliefs (a mixture of Gaussians, d = 20, float32),
build the index (kind auto unless --kind), then time `decompose` (k = 42) on batches of 100
queries that look like one control step: the beliefs of one state under 100 candidate actions,
y_i = base + A a_i with a_i uniform in [-1, 1]^2 and A a random (20, 2) matrix of scale
--spread (the action moves the belief along a 2-d subspace). Reported:

  build s       index build time (or load time, with --cache and an index built before)
  ms/batch      median over batches x repeats of neighbours + decomposition (wall clock)
  cpu ms        the same, process CPU time (all threads): less sensitive to other load
  recall        neighbour recall of the k = 42 rows against exact search (faiss flat)
  paper ms      the paper's procedure on the same queries, in torch, batched over the 100
                queries (so faster than one candidate at a time): distances to every belief,
                top-100, softmax weights fitted by 1000 Adam steps (lr 0.05)
  speed-up      paper ms / ms per batch
  no-ix ms      median of the same decompositions without an index (`decompose(beliefs, q)`:
                the index-free exact search, aoc_cli/index/search/exact.py), timed batch by batch
                interleaved with the indexed calls
  ratio         no-ix ms / ms per batch (both from this run)
  mem x         memory of the beliefs + index + querying, in units of the belief array:
                (belief array + peak resident growth while building and querying) / belief array

One row per size (``work``: the 100 queries of a batch; ``median_s``: ms per batch in seconds).

Usage: .venv/bin/python benchmarks/perf/decompose.py --sizes 100k,600k,10M [-f json]
"""

from __future__ import annotations

import os
import sys
import time

import _harness as h

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import faiss  # noqa: E402
import numpy as np  # noqa: E402

from aoc_cli.decompose import decompose  # noqa: E402
from aoc_cli.index import BeliefIndex, IndexConfig  # noqa: E402

D = 20
K = 42


def generate(n: int, seed: int = 0, centres: int = 2000) -> np.ndarray:
    """Mixture of Gaussians, built in chunks (no float64 copy of the whole array)."""
    rng = np.random.default_rng(seed)
    means = (rng.standard_normal((centres, D)) * 3).astype(np.float32)
    scales = rng.uniform(0.2, 1.0, centres).astype(np.float32)
    axes = rng.uniform(0.3, 1.0, (centres, D)).astype(np.float32)  # anisotropic clusters
    out = np.empty((n, D), dtype=np.float32)
    for start in range(0, n, 1_000_000):
        stop = min(n, start + 1_000_000)
        which = rng.integers(0, centres, stop - start)
        noise = rng.standard_normal((stop - start, D), dtype=np.float32)
        out[start:stop] = means[which] + noise * (scales[which, None] * axes[which])
    return out


def control_steps(beliefs: np.ndarray, n_batches: int, q: int, spread: float, seed: int) -> list[np.ndarray]:
    rng = np.random.default_rng(seed)
    batches = []
    for _ in range(n_batches):
        base = beliefs[rng.integers(len(beliefs))] + 0.05 * rng.standard_normal(D)
        A = spread * rng.standard_normal((D, 2))
        actions = rng.uniform(-1, 1, (q, 2))
        batches.append((base + actions @ A.T).astype(np.float64))
    return batches


def rss_mb(field: str = "VmRSS") -> float:
    with open("/proc/self/status") as f:
        for line in f:
            if line.startswith(field + ":"):
                return int(line.split()[1]) / 1024
    return float("nan")


def reset_peak() -> None:
    try:
        with open("/proc/self/clear_refs", "w") as f:
            f.write("5")
    except OSError:
        pass


def paper_procedure(beliefs_t, queries: np.ndarray, steps: int = 1000) -> float:
    """The paper's code path, batched over the candidates: seconds for one batch."""
    import torch

    t0 = time.perf_counter()
    Y = torch.from_numpy(queries.astype(np.float32))
    best_d, best_i = None, None
    chunk = 1_000_000
    for start in range(0, beliefs_t.shape[0], chunk):
        part = beliefs_t[start : start + chunk]
        d = torch.cdist(Y, part)
        dv, di = torch.topk(d, 100, dim=1, largest=False)
        di = di + start
        if best_d is None:
            best_d, best_i = dv, di
        else:
            cat_d, cat_i = torch.cat([best_d, dv], 1), torch.cat([best_i, di], 1)
            best_d, order = torch.topk(cat_d, 100, dim=1, largest=False)
            best_i = torch.gather(cat_i, 1, order)
    B = beliefs_t[best_i]  # (Q, 100, d)
    logits = torch.zeros(B.shape[:2], requires_grad=True)
    opt = torch.optim.Adam([logits], lr=0.05)
    for _ in range(steps):
        opt.zero_grad()
        w = torch.softmax(logits, dim=1)
        loss = ((torch.einsum("qk,qkd->qd", w, B) - Y) ** 2).sum()
        loss.backward()
        opt.step()
    return time.perf_counter() - t0


def run(n: int, args) -> dict:
    cache = None
    if args.cache:
        os.makedirs(args.cache, exist_ok=True)
        cache = os.path.join(args.cache, f"beliefs-{n}-{args.seed}-{args.kind}")
    t = time.perf_counter()
    if cache and os.path.exists(cache + ".npy"):
        beliefs = np.load(cache + ".npy")
    else:
        beliefs = generate(n, seed=args.seed)
        if cache:
            np.save(cache + ".npy", beliefs)
    gen_s = time.perf_counter() - t
    values = np.random.default_rng(1).standard_normal(n).astype(np.float32)
    base_rss = rss_mb()
    reset_peak()
    t = time.perf_counter()
    config = IndexConfig(kind=args.kind, threads=args.threads,
                         **({"ivf_nprobe": args.nprobe} if args.nprobe else {}))
    if cache and os.path.exists(cache + ".faiss"):
        index = BeliefIndex.load(cache + ".faiss", beliefs=beliefs)
        index.config = config  # search parameters of this run (nprobe, pool), not the saved ones
    else:
        index = BeliefIndex.build(beliefs, config)
        if cache:
            index.save(cache + ".faiss")
    build_s = time.perf_counter() - t
    batches = control_steps(beliefs, args.batches, 100, args.spread, seed=args.seed + 1)

    decompose(beliefs, batches[0], k=K, values=values, index=index)  # warm-up
    decompose(beliefs, batches[0], k=K, values=values)  # warm-up (compiles the exact search)
    times, cpu, plain, fallbacks, full = [], [], [], 0, 0
    results = []
    for _ in range(args.repeats):
        for queries in batches:
            t, c = time.perf_counter(), time.process_time()
            res = decompose(beliefs, queries, k=K, values=values, index=index)
            times.append(time.perf_counter() - t)
            cpu.append(time.process_time() - c)
            fallbacks += res.fallbacks
            results.append(res)
            if not args.no_plain:
                t = time.perf_counter()
                decompose(beliefs, queries, k=K, values=values)
                plain.append(time.perf_counter() - t)
    full = float(np.mean([(r.residual == 0).mean() for r in results]))
    support = float(np.mean([(r.rows >= 0).sum(1).mean() for r in results]))
    peak = rss_mb("VmHWM")
    mem_ratio = 1.0 + (peak - base_rss) * 2**20 / beliefs.nbytes

    # recall against exact search (outside the timing)
    flat = faiss.IndexFlatL2(D)
    flat.add(beliefs)
    recalls = []
    for queries, res in zip(batches[: args.recall_batches], results):
        _, truth = flat.search(queries.astype(np.float32), K)
        recalls.extend(len(set(a) & set(b)) / K for a, b in zip(res.neighbours, truth))
    del flat

    paper_s = float("nan")
    if args.paper_batches > 0:
        import torch

        torch.set_num_threads(args.threads or 2)
        bt = torch.from_numpy(beliefs)
        paper_s = float(np.median([paper_procedure(bt, q) for q in batches[: args.paper_batches]]))
    ms = float(np.median(times) * 1e3)
    return h.row(
        f"{n} rows", len(batches[0]), h.Runs(times, cpu, [None] * len(times)), unit="queries",
        rows=n,
        kind=index.kind,
        gen_s=gen_s,
        build_s=build_s,
        ms=ms,
        p90_ms=float(np.percentile(times, 90) * 1e3),
        cpu_ms=float(np.median(cpu) * 1e3),
        recall=float(np.mean(recalls)),
        min_recall=float(np.min(recalls)),
        paper_ms=paper_s * 1e3,
        speedup=paper_s * 1e3 / ms,
        mem_ratio=mem_ratio,
        plain_ms=float(np.median(plain) * 1e3) if plain else float("nan"),
        ratio=float(np.median(plain) * 1e3) / ms if plain else float("nan"),
        inside=full,
        support=support,
        fallbacks=fallbacks,
    )


def main(argv=None) -> int:
    parser = h.parser(__doc__)
    parser.add_argument("--sizes", default="100k,600k", help="comma-separated corpus sizes, e.g. 100k,600k,10M")
    parser.add_argument("--kind", default="auto", choices=["auto", "flat", "hnsw", "ivf"])
    parser.add_argument("--batches", type=int, default=20, help="distinct control steps per size")
    parser.add_argument("--repeats", type=int, default=3, help="timed runs of each batch")
    parser.add_argument("--recall-batches", type=int, default=10)
    parser.add_argument("--paper-batches", type=int, default=2, help="batches run through the paper's procedure")
    parser.add_argument("--spread", type=float, default=0.1, help="scale of the action directions in belief space")
    parser.add_argument("--threads", type=int, default=2, help="FAISS / torch threads")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--nprobe", type=int, default=0, help="IVF lists visited (0: IndexConfig default)")
    parser.add_argument("--no-plain", action="store_true", help="skip the timing without an index")
    parser.add_argument("--cache", default="", help="folder to keep generated beliefs and built indexes in")
    args = parser.parse_args(argv)
    faiss.omp_set_num_threads(args.threads)
    print(f"# d={D} k={K} batch=100 spread={args.spread} threads={args.threads} "
          f"load={h.load():.1f}\n# {' '.join(sys.argv)}", file=sys.stderr)
    h.emit([run(n, args) for n in h.sizes(args.sizes)], args.format)
    return 0


if __name__ == "__main__":
    sys.exit(main())
