"""A synthetic ICU cohort table shaped like the AI Clinician's MIMIC-III sepsis cohort
(Komorowski et al. 2018): one row per stay per 4-hour bloc, demographics, vitals and labs with
empty cells, two continuous doses and the outcome once per stay.

    python scripts/cohort.py cohort.csv --stays 300 --seed 0        # CSV (.csv.gz, .parquet)

Columns: ``icustayid``, ``bloc``, ``charttime`` (seconds), ``gender``, ``age``,
``elixhauser``, ``re_admission`` (constant within a stay), ``LABS`` vitals and labs,
``input_4hourly`` (mL of fluid in the bloc) and ``max_dose_vaso`` (mcg/kg/min; 0 when none),
``died_in_hosp`` and ``mortality_90d`` (0/1, the same on every row of a stay; empty for a stay
cut short, ``censored`` share of them). 51 columns in all with the default 40 vitals and labs.

Each stay follows a latent severity s_t (an AR(1) walk): vitals and labs read it with noise;
the clinicians' doses rise with it (fluids at about 70% of blocs, vasopressors when it is high)
and lower it a little; the probability of death rises with the last s_t (logit 2.5 s_T - 1.2).
Vitals are empty at
``gap / 3`` of the blocs, labs at ``gap * 1.6`` (overall about ``gap`` of those cells); the
first bloc may be empty too (``--impute hold`` then falls back to the median). Used by
docs/guide/clinical.md, the tests (``tests/formats/test_cohort.py``) and
benchmarks/perf/ingest.py.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

#: Vitals first (measured every bloc), then labs (drawn less often).
VITALS = ["HR", "SysBP", "MeanBP", "DiaBP", "RR", "SpO2", "Temp_C", "GCS", "FiO2_1", "Shock_Index"]
LABS = ["Potassium", "Sodium", "Chloride", "Glucose", "BUN", "Creatinine", "Magnesium",
        "Calcium", "Ionised_Ca", "CO2_mEqL", "SGOT", "SGPT", "Total_bili", "Albumin", "Hb",
        "WBC_count", "Platelets_count", "PTT", "PT", "INR", "Arterial_pH", "paO2", "paCO2",
        "Arterial_BE", "HCO3", "Arterial_lactate", "SOFA", "SIRS", "PaO2_FiO2", "cumulated_balance"]
def _params(names, seed=1234):
    """(mean, spread, how strongly severity moves it) of each vital and lab."""
    rng = np.random.default_rng(seed)
    mean = rng.uniform(5, 150, len(names)).round(1)
    spread = (mean * rng.uniform(0.05, 0.2, len(names))).round(2)
    effect = rng.uniform(-1.0, 1.0, len(names))
    return mean, spread, effect


def cohort(stays: int = 300, seed: int = 0, gap: float = 0.15, censored: float = 0.03,
           labs: int = 40, blocs: tuple[int, int] = (8, 20)) -> dict[str, np.ndarray]:
    """The cohort's columns, rows ordered by stay then bloc: {name: (N,) array}; empty cells
    are NaN (written as empty CSV cells)."""
    rng = np.random.default_rng(seed)
    names = (VITALS + LABS)[:labs] if labs <= len(VITALS + LABS) else \
        VITALS + LABS + [f"lab_{j}" for j in range(labs - len(VITALS + LABS))]
    mean, spread, effect = _params(names)
    lengths = rng.integers(blocs[0], blocs[1] + 1, stays)
    n = int(lengths.sum())
    stay = np.repeat(np.arange(stays), lengths)
    starts = np.concatenate([[0], np.cumsum(lengths)])
    bloc = np.arange(n) - starts[stay] + 1
    # latent severity, the clinicians' doses, and the doses' effect on it
    s = np.empty(n)
    fluid = np.zeros(n)
    vaso = np.zeros(n)
    s0 = rng.normal(0.0, 1.0, stays)
    noise = rng.normal(0.0, 0.35, n)
    gives_fluid = rng.random(n) < 0.7
    fluid_amount = np.exp(rng.normal(5.0, 1.0, n))
    vaso_amount = np.exp(rng.normal(-2.0, 0.8, n))
    for i in range(n):  # a short loop: the AR(1) walk of each stay
        prev = s0[stay[i]] if bloc[i] == 1 else s[i - 1] - 0.0006 * fluid[i - 1] \
            - 0.6 * vaso[i - 1]
        s[i] = 0.85 * prev + noise[i]
        fluid[i] = (fluid_amount[i] * (1 + 0.3 * max(s[i], 0))) if gives_fluid[i] else 0.0
        vaso[i] = vaso_amount[i] * (1 + s[i]) if s[i] > 0.8 else 0.0
    cols: dict[str, np.ndarray] = {
        "icustayid": 200000 + 7 * np.arange(stays)[stay],
        "bloc": bloc,
        "charttime": 4_000_000_000 + 10_000_000 * np.arange(stays)[stay] + 14400 * bloc,
        "gender": rng.integers(0, 2, stays)[stay],
        "age": rng.uniform(18 * 365, 90 * 365, stays).round(0)[stay],
        "elixhauser": rng.integers(0, 12, stays)[stay],
        "re_admission": rng.integers(0, 2, stays)[stay],
    }
    measured = np.empty((n, len(names)), bool)
    for j, name in enumerate(names):
        values = mean[j] + spread[j] * (effect[j] * s + rng.normal(0, 0.5, n))
        share = gap / 3 if j < len(VITALS) else gap * 1.6
        measured[:, j] = rng.random(n) >= share
        cols[name] = np.where(measured[:, j], values.round(2), np.nan)
    cols["input_4hourly"] = fluid.round(1)
    cols["max_dose_vaso"] = vaso.round(3)
    last = starts[1:] - 1
    p_death = 1 / (1 + np.exp(-(2.5 * s[last] - 1.2)))
    died = (rng.random(stays) < p_death).astype(float)
    late = np.where(rng.random(stays) < 0.3, 1.0, died)
    cut = rng.random(stays) < censored
    died[cut] = np.nan
    late[cut] = np.nan
    cols["died_in_hosp"] = died[stay]
    cols["mortality_90d"] = late[stay]
    return cols


def to_table(cols: dict[str, np.ndarray]):
    """The columns as an Arrow table (NaN cells null; integer columns as integers)."""
    import pyarrow as pa  # lazy: the generator itself needs numpy only

    out = {}
    for k, v in cols.items():
        if v.dtype.kind == "f" and np.isnan(v).any():
            out[k] = pa.array(v, mask=np.isnan(v))
        else:
            out[k] = pa.array(v)
    return pa.table(out)


def write(cols: dict[str, np.ndarray], path: Path) -> Path:
    """Write the cohort as CSV (``.csv``, ``.csv.gz``) or Parquet (``.parquet``); empty
    cells empty."""
    import pyarrow.csv as pacsv  # lazy: see to_table
    import pyarrow.parquet as pq

    path = Path(path)
    table = to_table(cols)
    if path.suffix == ".parquet":
        pq.write_table(table, path)
        return path
    import pyarrow as pa  # lazy: see to_table

    header = (",".join(table.column_names) + "\n").encode()
    options = pacsv.WriteOptions(include_header=False, quoting_style="none")
    with (pa.CompressedOutputStream(str(path), "gzip") if path.suffix == ".gz"
          else pa.OSFile(str(path), "wb")) as out:
        out.write(header)
        pacsv.write_csv(table, out, options)
    return path


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("out", type=Path, help="cohort.csv, cohort.csv.gz or cohort.parquet")
    parser.add_argument("--stays", type=int, default=300)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--gap", type=float, default=0.15,
                        help="share of the vital and lab cells left empty")
    parser.add_argument("--censored", type=float, default=0.03,
                        help="share of stays cut short (outcome empty)")
    parser.add_argument("--labs", type=int, default=40, help="vitals and labs")
    args = parser.parse_args(argv)
    cols = cohort(args.stays, args.seed, args.gap, args.censored, args.labs)
    write(cols, args.out)
    rows = len(cols["icustayid"])
    print(f"{args.out}: {args.stays} stays, {rows} rows, {len(cols)} columns")


if __name__ == "__main__":
    main()
