"""The columnar ingest of a clinical cohort (streamed CSV -> numpy columns -> filled in place ->
rows made block by block in the store) against a straightforward reference written here from
the rules alone: Python's csv module, rows sorted by (stay, bloc), loops over the cells. Gaps
(hold and median), dose bins, the outcome as the last reward and censored stays (an empty
outcome, a censoring column) must come out the same, value for value, whatever the file's row
order and compression."""

import csv
import gzip
import os
import subprocess
import sys

import numpy as np
import pytest

import aoc_cli
from aoc_cli.store import Store
from tests.formats.cohorts import OBS, ROOT, cohort, roles, write

BINS = {"input_4hourly": 4, "max_dose_vaso": 3}
REWARD = {1.0: -1.0, 0.0: 1.0}


def reference(path, rule):
    """The corpus arrays, computed cell by cell from the CSV text."""
    opener = gzip.open if str(path).endswith(".gz") else open
    with opener(path, "rt", newline="") as fh:
        rows = list(csv.DictReader(fh))
    rows.sort(key=lambda r: (float(r["icustayid"]), float(r["bloc"])))
    num = [{k: (float(v) if v.strip() else np.nan) for k, v in r.items()} for r in rows]
    n = len(num)
    stay = [r["icustayid"] for r in num]
    raw = np.array([[r[c] for c in OBS] for r in num])
    gaps = [c for j, c in enumerate(OBS) if np.isnan(raw[:, j]).any()]
    medians = [float(np.median(raw[~np.isnan(raw[:, j]), j])) for j in range(len(OBS))]
    filled = raw.copy()
    for j in range(len(OBS)):
        last = None
        for i in range(n):
            if i == 0 or stay[i] != stay[i - 1]:
                last = None
            if np.isnan(raw[i, j]):
                filled[i, j] = last if rule == "hold" and last is not None else medians[j]
            else:
                last = raw[i, j]
    features = np.array([[0.0 if np.isnan(raw[i, OBS.index(c)]) else 1.0 for c in gaps]
                         for i in range(n)])
    observations = np.concatenate([filled, features], axis=1)
    imputed = np.concatenate([np.isnan(raw), np.zeros((n, len(gaps)), bool)], axis=1)
    action = np.zeros(n, np.int64)
    edges = {}
    for col, k in BINS.items():
        dose = np.array([r[col] for r in num])
        nonzero = dose[dose > 0]
        cuts = np.quantile(nonzero, np.arange(1, k - 1) / (k - 1))
        edges[col] = [float(nonzero.min()), *map(float, cuts), float(nonzero.max())]
        level = np.array([0 if d == 0 else 1 + sum(d >= c for c in cuts) for d in dose])
        action = action * k + level
    ends = [i for i in range(n) if i == n - 1 or stay[i + 1] != stay[i]]
    rewards, terminals, truncations = np.zeros(n), np.zeros(n, bool), np.zeros(n, bool)
    for i in ends:
        first = max(k for k in range(i + 1) if k == 0 or stay[k] != stay[k - 1])
        outcome = num[i]["died_in_hosp"]
        cut = np.isnan(outcome) or any(num[k]["transferred"] for k in range(first, i + 1))
        if not np.isnan(outcome):
            rewards[i] = REWARD[outcome]
        truncations[i], terminals[i] = cut, not cut
    return dict(observations=observations, imputed=imputed, actions=action, rewards=rewards,
                terminals=terminals, truncations=truncations, medians=medians, edges=edges,
                names=OBS + [f"{c}?measured" for c in gaps],
                ids=list(dict.fromkeys(r["icustayid"] for r in rows)),
                columns={c: np.array([r[c] for r in num]) for c in ("charttime", "mortality_90d")})


@pytest.mark.parametrize("rule,order,suffix", [("hold", "sorted", ".csv"),
                                               ("hold", "shuffled", ".csv"),
                                               ("median", "shuffled", ".csv.gz")])
def test_the_columnar_ingest_gives_the_reference_arrays(tmp_path, rule, order, suffix):
    cols = cohort(60, seed=5, censored=0.1)
    rng = np.random.default_rng(1)
    stays = np.unique(cols["icustayid"])
    moved = np.isin(cols["icustayid"], rng.choice(stays, 5, replace=False))
    cols["transferred"] = moved.astype(float)  # 5 stays cut short by the censoring column
    if order == "shuffled":
        perm = rng.permutation(len(cols["icustayid"]))
        cols = {k: v[perm] for k, v in cols.items()}
    path = write(cols, tmp_path / f"c{suffix}")
    store = Store(tmp_path / "s")
    aoc_cli.ingest(path, "icu", store=store, options=roles(
        impute=rule, impute_mask=True,
        bin_actions=",".join(f"{c}={k}" for c, k in BINS.items()),
        outcome="died_in_hosp", outcome_reward="1=-1,0=1", censored_column="transferred"))
    c = store.corpus("icu")
    ref = reference(path, rule)
    assert c.observation_space["names"] == ref["names"]
    np.testing.assert_array_equal(c.observations, ref["observations"])
    np.testing.assert_array_equal(c.imputed_mask, ref["imputed"])
    np.testing.assert_array_equal(c.actions, ref["actions"])
    np.testing.assert_array_equal(c.rewards, ref["rewards"])
    np.testing.assert_array_equal(c.read("terminals"), ref["terminals"])
    np.testing.assert_array_equal(c.read("truncations"), ref["truncations"])
    assert ref["truncations"].sum() >= 5 and ref["terminals"].sum() >= 40
    assert c.preprocessing["impute"]["medians"] == ref["medians"]
    assert c.preprocessing["bins"]["edges"] == ref["edges"]
    assert c.episode_ids == ref["ids"]
    for name, values in ref["columns"].items():
        np.testing.assert_array_equal(c.column(name), values)
    # the hash recomputed from the arrays read back is the one the writer computed as it went
    assert c.content_hash() == c.hash


def test_a_cohort_csv_is_ingested_without_importing_pandas(tmp_path):
    """pyarrow's ``to_numpy`` goes through its pandas layer, which imports pandas (~0.5 s and
    ~50 MB in a fresh process, more than a small ingest); the CSV path reads Arrow buffers."""
    path = write(cohort(20, seed=2), tmp_path / "c.csv")
    options = roles(impute="hold", impute_mask=True, outcome="died_in_hosp",
                    outcome_reward="1=-1,0=1", bin_actions="input_4hourly=3,max_dose_vaso=3")
    store = str(tmp_path / "s")
    code = "\n".join([
        "import sys, aoc_cli",
        "from aoc_cli.store import Store",
        f"aoc_cli.ingest({str(path)!r}, 'icu', store=Store({store!r}), options={options!r})",
        f"assert Store({store!r}).corpus('icu').n_rows > 0",
        "print('pandas' in sys.modules)"])
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         env={**os.environ, "PYTHONPATH": str(ROOT)}, check=True)
    assert out.stdout.strip() == "False"
