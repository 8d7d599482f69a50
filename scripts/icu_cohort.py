"""A clinical cohort table drawn from the ICU-Sepsis MDP: a test bed with a known truth.

    python scripts/icu_cohort.py cohort.csv --stays 5000 --seed 0     # CSV (.csv.gz, .parquet)
    aoc ingest cohort.csv --name c --discrete-actions --impute hold \\
        --outcome died_in_hosp --outcome-reward 1=0,0=1
    aoc train c && aoc index c
    aoc rollout c --env icu-cohort --episodes 2000                   # the true survival

One row per stay per 4-hour step; the patients follow the icu-sepsis package's MDP treated by
the clinicians' estimated policy (aoc_cli/envs/icu_sepsis.py). Columns (their names are those
``aoc ingest`` finds by itself): ``id`` (the stay), ``time`` (its step, 1-based), the 47
AI-Clinician features ``obs_gender`` ... ``obs_output_4hourly`` (the true state's cluster
centre plus N(0, noise^2) per cell, in the package's normalised units; a ``--gap`` share of the
cells empty, never on a stay's first step), ``act_dose`` (the clinicians' dose level
``5 * fluids + vaso``, 0-24) and ``died_in_hosp`` (0/1 on every row of the stay; empty for a
stay cut short, a ``--censored`` share of them). The environment ``icu-cohort`` (``aoc rollout
--env icu-cohort:noise=0.3,gap=0.15``) replays the same MDP through the same noise and gaps.

``--truth FILE`` also writes each row's hidden truth (``id``, ``time``, ``state``: the MDP's
state, ``propensity``: the clinicians' probability of the logged dose in it). The columns are
made by :func:`aoc_cli.envs.icu_cohort.cohort_table` (same arguments, same table).
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np


def to_table(cols: dict[str, np.ndarray], names):
    """The columns ``names`` as an Arrow table (NaN cells null; floats as float32, written with
    the fewest digits that read back to the same float32)."""
    import pyarrow as pa

    out = {}
    for k in names:
        v = cols[k]
        if v.dtype.kind == "f":
            out[k] = pa.array(v, mask=np.isnan(v)) if np.isnan(v).any() else pa.array(v)
        else:
            out[k] = pa.array(v)
    return pa.table(out)


def write(cols: dict[str, np.ndarray], path: Path, names) -> Path:
    """Write the columns ``names`` as CSV (``.csv``, ``.csv.gz``) or Parquet (``.parquet``);
    empty cells empty."""
    import pyarrow as pa
    import pyarrow.csv as pacsv
    import pyarrow.parquet as pq

    path = Path(path)
    table = to_table(cols, names)
    if path.suffix == ".parquet":
        pq.write_table(table, path)
        return path
    header = (",".join(table.column_names) + "\n").encode()
    options = pacsv.WriteOptions(include_header=False, quoting_style="none")
    with (pa.CompressedOutputStream(str(path), "gzip") if path.suffix == ".gz"
          else pa.OSFile(str(path), "wb")) as out:
        out.write(header)
        pacsv.write_csv(table, out, options)
    return path


def main(argv=None) -> None:
    from aoc_cli.envs import icu_cohort

    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("out", type=Path, help="cohort.csv, cohort.csv.gz or cohort.parquet")
    parser.add_argument("--stays", type=int, default=5000)
    parser.add_argument("--noise", type=float, default=icu_cohort.NOISE,
                        help="sd of the Gaussian noise on every feature cell")
    parser.add_argument("--gap", type=float, default=icu_cohort.GAP,
                        help="share of the feature cells left empty (not on a first step)")
    parser.add_argument("--censored", type=float, default=icu_cohort.CENSORED,
                        help="share of stays cut short (outcome empty)")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--truth", type=Path, default=None,
                        help="also write id, time, state, propensity of every row here")
    args = parser.parse_args(argv)
    start = time.perf_counter()
    cols = icu_cohort.cohort_table(args.stays, args.noise, args.gap, args.censored, args.seed)
    names = [k for k in cols if k not in icu_cohort.HIDDEN]
    write(cols, args.out, names)
    if args.truth is not None:
        write(cols, args.truth, [icu_cohort.ID, icu_cohort.TIME, *icu_cohort.HIDDEN])
    rows = len(cols[icu_cohort.ID])
    first = np.ones(rows, dtype=bool)
    first[1:] = cols[icu_cohort.ID][1:] != cols[icu_cohort.ID][:-1]
    censored = int(np.isnan(cols[icu_cohort.OUTCOME][first]).sum())
    print(f"{args.out}: {args.stays} stays ({censored} censored), {rows} rows, {len(names)} "
          f"columns ({time.perf_counter() - start:.1f} s)")


if __name__ == "__main__":
    main()
