"""Ingest benchmark (issue 2): a generated 1M-row D4RL-style file (17-d observations, 6-d
actions) into the store, and history lookups for 100k random rows; with ``--cohort``, a
clinical cohort table beside pyarrow's own ``read_csv`` of it (issue 37).

    .venv/bin/python benchmarks/perf/ingest.py [--rows 1000000] [--repeats 5] [--compare-compression]
    .venv/bin/python benchmarks/perf/ingest.py --cohort [--stays 16400] [--repeats 3]

``--cohort``: scripts/cohort.py's table (16,400 stays of 8-20 blocs: ~230k rows x 51 columns,
15% of the vital and lab cells empty) written as CSV; then, round by round in fresh processes
(so that each peak resident memory, VmHWM, is its own; the imports before the clock and
the memory baseline), ``pyarrow.csv.read_csv`` of the file and ``aoc_cli.ingest`` of it with the clinical flags (``--impute hold --impute-mask
--bin-actions input_4hourly=5,max_dose_vaso=5 --outcome died_in_hosp``), the store written
included. Goal: the ingest within 3x of read_csv's time, its peak memory (above what the
imports hold) <= 3x the file's size.

Goal: >= 1M rows/s for ingest; < 1 s for the histories (L = 4) of 100k random rows.
The generated data are smooth random walks within 1000-step episodes (like logged control
trajectories: consecutive observations are close), actions uniform in [-1, 1], rewards normal;
an episode ends every 1000 rows, alternately by a terminal and a timeout. The source file is
written uncompressed (as a file straight from a simulator's logger would be). Rows: the
library call (``aoc_cli.ingest``), the command (``aoc ingest`` in a fresh process), the history
lookups cold (open the corpus + look up) and warm; the median of ``--repeats`` runs, and each
run's time.
"""

from __future__ import annotations

import os
import sys
import tempfile
from pathlib import Path

import _harness as h
import h5py
import numpy as np

import aoc_cli
from aoc_cli.formats.ingest import read_dataset
from aoc_cli.store import Store


def generate(path: Path, rows: int, d_o: int = 17, d_a: int = 6, episode: int = 1000,
             seed: int = 0) -> None:
    rng = np.random.default_rng(seed)
    steps = rng.standard_normal((rows, d_o)).astype(np.float32) * 0.05
    starts = np.arange(0, rows, episode)
    steps[starts] = rng.standard_normal((len(starts), d_o)).astype(np.float32)
    obs = np.cumsum(steps, axis=0, dtype=np.float32)
    # restart the walk at every episode start
    offsets = np.repeat(obs[starts] - steps[starts], np.diff(np.append(starts, rows)), axis=0)
    obs -= offsets
    ends = np.minimum(starts + episode, rows) - 1
    terminals = np.zeros(rows, bool)
    timeouts = np.zeros(rows, bool)
    terminals[ends[0::2]] = True
    timeouts[ends[1::2]] = True
    with h5py.File(path, "w") as f:
        f["observations"] = obs
        f["actions"] = rng.uniform(-1, 1, (rows, d_a)).astype(np.float32)
        f["rewards"] = rng.standard_normal(rows).astype(np.float32)
        f["terminals"] = terminals
        f["timeouts"] = timeouts


def time_ingest(src: Path, store_root: Path, repeats: int,
                float_opts: dict | None = None) -> h.Runs:
    """Runs of ingesting ``src`` (the API entry); with ``float_opts``, of reading it and
    writing it with those dataset options for the float columns (Store.write's
    ``float_opts``, no API entry has them)."""
    store = Store(store_root)
    if float_opts is None:
        return h.repeat(lambda _: aoc_cli.ingest(src, "bench", store=store, overwrite=True),
                        repeats)
    return h.repeat(lambda _: store.write("bench", read_dataset(src, None, None),
                                          overwrite=True, float_opts=float_opts), repeats)


def time_history(store_root: Path, repeats: int, lookups: int = 100_000,
                 length: int = 4) -> tuple[h.Runs, h.Runs]:
    """(cold: open the corpus and look up, warm: a second lookup on the open corpus)."""
    rng = np.random.default_rng(1)
    cold, warm = h.Runs(), h.Runs()
    for _ in range(repeats):
        rows = rng.integers(0, Store(store_root).corpus("bench").n_rows, lookups)
        corpus, wall, cpu = h.timed(lambda: Store(store_root).corpus("bench"))
        hist, wall2, cpu2 = h.timed(lambda: corpus.history(rows, length))
        cold.add(wall + wall2, cpu + cpu2)
        rows = rng.integers(0, corpus.n_rows, lookups)
        hist, wall, cpu = h.timed(lambda: corpus.history(rows, length))
        warm.add(wall, cpu)
        assert hist.observations.shape == (lookups, length, corpus.observation_dim)
    return cold, warm


def compare_compression(src: Path, root: Path, repeats: int) -> list[dict]:
    settings = {
        "none (contiguous)": {},
        "lzf": dict(compression="lzf"),
        "lzf + shuffle": dict(compression="lzf", shuffle=True),
        "gzip-1": dict(compression="gzip", compression_opts=1),
        "gzip-1 + shuffle": dict(compression="gzip", compression_opts=1, shuffle=True),
    }
    out = []
    for label, opts in settings.items():
        folder = root / label.replace(" ", "_")
        runs = time_ingest(src, folder, repeats, float_opts=opts)
        cold, warm = time_history(folder, repeats)
        size = (folder / "bench" / "corpus.h5").stat().st_size
        out.append(h.row(f"float columns {label}", None, runs, size_mb=size / 1e6,
                         history_cold_s=cold.median, history_warm_s=warm.median))
    return out


#: A child process: the imports, then one timed case; prints seconds and memory as JSON.
CHILD = """
import json, resource, sys, time
from pathlib import Path
case, src, store = sys.argv[1], sys.argv[2], sys.argv[3]
import numpy, pyarrow, pyarrow.csv
if case == "aoc":
    import aoc_cli, aoc_cli.store, aoc_cli.formats.ingest
    ingest = aoc_cli.ingest  # the API's lazy import, before the clock starts
def hwm():
    for line in Path("/proc/self/status").read_text().splitlines():
        if line.startswith("VmHWM"):
            return int(line.split()[1]) / 1024
def cpu():
    r = resource.getrusage(resource.RUSAGE_SELF)  # every thread of the process
    return r.ru_utime + r.ru_stime
before = hwm()
c0 = cpu()
t0 = time.perf_counter()
if case == "pyarrow":
    table = pyarrow.csv.read_csv(src)
    rows = table.num_rows
else:
    obs = [c for c in Path(src).open().readline().strip().split(",")
           if c not in ("icustayid", "bloc", "charttime", "input_4hourly", "max_dose_vaso",
                        "died_in_hosp", "mortality_90d")]
    result = ingest(src, "bench", store=aoc_cli.store.Store(store), overwrite=True,
                            options=dict(id_column="icustayid", time_column="bloc",
                                         obs_columns=obs, impute="hold", impute_mask=True,
                                         bin_actions="input_4hourly=5,max_dose_vaso=5",
                                         outcome="died_in_hosp", outcome_reward="1=-1,0=1"))
    rows = result.rows
print(json.dumps({"seconds": time.perf_counter() - t0, "cpu": cpu() - c0, "rows": rows,
                  "hwm_imports_mb": before,
                  "hwm_mb": hwm(), "pandas_imported": "pandas" in sys.modules}))
"""


def cohort_rows(tmp: Path, stays: int, repeats: int) -> list[dict]:
    """pyarrow's read_csv and aoc's ingest of one generated cohort CSV, interleaved."""
    import importlib.util
    import json
    import subprocess

    spec = importlib.util.spec_from_file_location("cohort", h.ROOT / "scripts" / "cohort.py")
    script = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(script)
    src = script.write(script.cohort(stays, seed=0), tmp / "cohort.csv")
    size_mb = src.stat().st_size / 1e6
    cols = src.open().readline().count(",") + 1
    print(f"source: {src.name}, {size_mb:.1f} MB, {cols} columns, {os.cpu_count()} cores, "
          f"load {h.load():.1f}", file=sys.stderr)
    env = {**os.environ, "PYTHONPATH": str(h.ROOT)}
    runs = {"pyarrow": [], "aoc": []}
    for _ in range(repeats):
        for case in runs:
            out = subprocess.run([sys.executable, "-c", CHILD, case, str(src),
                                  str(tmp / "store")], capture_output=True, text=True,
                                 env=env, check=True)
            runs[case].append(json.loads(out.stdout))
    rows = []
    for case, label in (("pyarrow", "pyarrow.csv.read_csv"),
                        ("aoc", "aoc_cli.ingest (clinical flags, store written)")):
        r = runs[case]
        t = h.Runs()
        for x in r:
            t.add(x["seconds"], x["cpu"])
        peak = sorted(x["hwm_mb"] - x["hwm_imports_mb"] for x in r)[len(r) // 2]
        rows.append(h.row(label, r[0]["rows"], t, file_mb=round(size_mb, 1),
                          pandas_imported=any(x["pandas_imported"] for x in r),
                          peak_above_imports_mb=round(peak, 1),
                          peak_over_file=round(peak / size_mb, 2),
                          peak_total_mb=round(sorted(x["hwm_mb"] for x in r)[len(r) // 2], 1)))
    for key, what in (("seconds", "wall"), ("cpu", "CPU")):
        ratios = sorted(a[key] / p[key] for a, p in zip(runs["aoc"], runs["pyarrow"]))
        print(f"ingest / read_csv, {what} seconds paired by round: median "
              f"{ratios[len(ratios) // 2]:.2f} (rounds {', '.join(f'{x:.2f}' for x in ratios)}); "
              f"load {h.load():.1f}", file=sys.stderr)
        rows.append({"case": f"ratio ingest / read_csv, {what} s (median of rounds)",
                     "median_s": ratios[len(ratios) // 2]})
    return rows


def main() -> None:
    parser = h.parser(__doc__, repeats=5)
    parser.add_argument("--cohort", action="store_true",
                        help="the clinical cohort CSV against pyarrow's read_csv instead")
    parser.add_argument("--stays", type=int, default=16_400, help="--cohort: stays")
    parser.add_argument("--rows", type=int, default=1_000_000)
    parser.add_argument("--lookups", type=int, default=100_000, help="history lookups")
    parser.add_argument("--compare-compression", action="store_true")
    parser.add_argument("--workdir", type=Path, default=None,
                        help="where to write the file and store (default: a temporary folder)")
    args = parser.parse_args()
    with tempfile.TemporaryDirectory(dir=args.workdir) as tmp:
        tmp = Path(tmp)
        if args.cohort:
            h.emit(cohort_rows(tmp, args.stays, args.repeats), args.format)
            return
        src = tmp / "generated.hdf5"
        generate(src, args.rows)
        print(f"source: {args.rows} rows, {src.stat().st_size / 1e6:.0f} MB, "
              f"{os.cpu_count()} cores", file=sys.stderr)
        rows = [h.row("ingest (library call)", args.rows,
                      time_ingest(src, tmp / "store", args.repeats))]
        cli = h.interleave({"cli": lambda _: h.aoc(
            ["ingest", str(src), "--name", "bench-cli", "--overwrite", "-f", "json"],
            store=tmp / "store")}, max(3, args.repeats // 2))["cli"]
        rows.append(h.row("aoc ingest (whole process)", args.rows, cli))
        cold, warm = time_history(tmp / "store", args.repeats, args.lookups)
        rows.append(h.row(f"history of {args.lookups} random rows, L=4, cold (open corpus + "
                          "lookup)", args.lookups, cold, unit="lookups"))
        rows.append(h.row(f"history of {args.lookups} random rows, L=4, warm", args.lookups,
                          warm, unit="lookups"))
        if args.compare_compression:
            rows += compare_compression(src, tmp / "cmp", args.repeats)
        h.emit(rows, args.format)


if __name__ == "__main__":
    main()
