"""One reader for CSV (plain, gzip), Parquet and in-memory frames (Arrow, pandas, polars):
the same columns give the same corpus, bit for bit."""

import numpy as np
import pandas as pd
import polars as pl
import pyarrow as pa

import aoc_cli
from aoc_cli.formats import ReadOptions, detect_format, read_dataset
from aoc_cli.store import Store
from tests.formats.cohorts import cohort, roles, script, write


def test_csv_gzip_parquet_and_frames_read_to_the_same_corpus(tmp_path):
    cols = cohort(stays=12, gap=0.0)
    options = roles(act_columns=["input_4hourly", "max_dose_vaso"], reward_free=True)
    store = Store(tmp_path / "s")
    sources = {"csv": write(cols, tmp_path / "c.csv"), "gz": write(cols, tmp_path / "c.csv.gz"),
               "parquet": write(cols, tmp_path / "c.parquet"), "arrow": script.to_table(cols)}
    sources["pandas"] = sources["arrow"].to_pandas()
    sources["polars"] = pl.from_arrow(sources["arrow"])
    assert detect_format(sources["parquet"]) == "parquet"
    assert detect_format(sources["gz"]) == "csv"
    hashes = {}
    for kind, source in sources.items():
        aoc_cli.ingest(source, kind, store=store, options=dict(options))
        hashes[kind] = store.corpus(kind).hash
    assert len(set(hashes.values())) == 1, hashes
    c = store.corpus("csv")
    n = len(cols["icustayid"])
    assert (c.n_rows, c.n_episodes) == (n, 12)
    np.testing.assert_array_equal(c.observations[:, 0], cols["age"])  # already in stay order
    np.testing.assert_array_equal(c.actions[:, 0], cols["input_4hourly"])
    assert c.load().episode_ids == [str(i) for i in np.unique(cols["icustayid"])]
    assert store.corpus("polars").manifest["sources"][0]["format"] == "frame"


def test_a_frame_in_any_row_order_is_sorted_by_stay_and_time(tmp_path):
    cols = cohort(stays=5, gap=0.0)
    perm = np.random.default_rng(0).permutation(len(cols["bloc"]))
    frame = pd.DataFrame({k: v[perm] for k, v in cols.items()})
    data = read_dataset(frame, options=ReadOptions(**roles(act_columns=["input_4hourly"])))
    np.testing.assert_array_equal(data.observations[:, 2], cols["HR"])
    assert data.source["frame"] == "DataFrame"


def test_ids_are_kept_as_written_and_text_tags_stay_text(tmp_path):
    path = tmp_path / "x.csv"
    path.write_text("episode,t,obs_a,act_u,ward\n007,0,1.5,0,1.0\n007,1,2.5,1,2.0\n8,0,3.5,0,1.0\n")
    data = read_dataset(path, options=ReadOptions(tag_columns=["ward"]))
    assert data.episode_ids == ["007", "8"]  # numeric ids sort numerically, text kept
    assert data.tags["ward"][1] == ["1.0", "2.0"]


def test_arrow_table_with_a_null_observation_is_refused_naming_the_worst_column(tmp_path):
    table = pa.table({"episode": [1, 1, 2], "obs_a": [1.0, None, 2.0], "obs_b": [1.0, 2, 3],
                      "act_u": [0.0, 1.0, 0.0]})
    try:
        read_dataset(table)
    except aoc_cli.AocError as err:
        assert "'obs_a' 33.3%" in str(err) and "impute" in str(err)
    else:
        raise AssertionError("a gap was taken silently")
