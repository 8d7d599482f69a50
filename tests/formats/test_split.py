"""aoc split: one cohort, two corpora; statistics and bins fitted on the training stays only,
the split recorded in both manifests."""

import json

import numpy as np
import pytest

import aoc_cli
from aoc_cli.errors import AocError
from aoc_cli.store import Store
from tests.formats.cohorts import OBS, cohort, roles, write


@pytest.fixture
def cohort_store(tmp_path):
    store = Store(tmp_path / "s")
    cols = cohort(stays=50, seed=3, gap=0.45)
    cols["hospital"] = np.array([f"h{int(i) % 4}" for i in cols["icustayid"] // 7])
    aoc_cli.ingest(write(cols, tmp_path / "c.csv"), "icu", store=store, options=roles(
        impute="hold", impute_mask=True, bin_actions="input_4hourly=5,max_dose_vaso=3",
        outcome="died_in_hosp", outcome_reward="1=-1,0=1", tag_columns=["hospital"]))
    return store, cols


def test_split_by_stay_refits_medians_and_bins_on_the_training_part(cohort_store):
    store, cols = cohort_store
    result = aoc_cli.split("icu", test=0.2, seed=0, store=store)
    assert [r["name"] for r in result.rows()] == ["icu-train", "icu-test"]
    whole, train, test = (store.corpus(n) for n in ("icu", "icu-train", "icu-test"))
    assert (train.n_episodes, test.n_episodes) == (40, 10)
    assert train.n_rows + test.n_rows == whole.n_rows
    ids_test = test.load().episode_ids
    assert not set(ids_test) & set(train.load().episode_ids)
    # medians of the training stays' measured cells only
    ids = cols["icustayid"].astype(str)
    in_train = ~np.isin(ids, ids_test)
    for j, name in enumerate(OBS):
        expect = float(np.nanmedian(cols[name][in_train]))
        assert train.preprocessing["impute"]["medians"][j] == pytest.approx(expect)
        assert test.preprocessing["impute"]["medians"][j] == pytest.approx(expect)
    nz = cols["input_4hourly"][in_train]
    nz = nz[nz > 0]
    edges = train.preprocessing["bins"]["edges"]["input_4hourly"]
    assert edges == pytest.approx([nz.min(), *np.quantile(nz, [0.25, 0.5, 0.75]), nz.max()])
    assert test.preprocessing["bins"] == train.preprocessing["bins"]
    # a test stay's imputed cell holds the training median (median rule at a stay's first row)
    first = test.episode_starts[:-1]
    cells = np.argwhere(test.imputed_mask[first, :len(OBS)])
    assert len(cells)
    medians = np.array(train.preprocessing["impute"]["medians"])
    np.testing.assert_allclose(test.observations[first[cells[:, 0]], cells[:, 1]],
                               medians[cells[:, 1]])
    # the measured features and the imputed cells are the same as in the whole corpus
    assert train.observation_space["names"] == whole.observation_space["names"]
    assert test.imputed_mask.sum() + train.imputed_mask.sum() == whole.imputed_mask.sum()
    for c in (train, test):
        split = c.preprocessing["split"]
        assert split["corpus"] == "icu" and split["content_hash"] == whole.hash
        assert split["seed"] == 0 and split["test_episodes"] == ids_test
    assert (train.preprocessing["split"]["part"], test.preprocessing["split"]["part"]) == \
        ("train", "test")


def test_split_by_a_tag_keeps_each_value_in_one_part(cohort_store):
    store, _cols = cohort_store
    aoc_cli.split("icu", test=0.3, seed=1, by="hospital", store=store,
                  names=("a", "b"))
    train, test = store.corpus("a"), store.corpus("b")
    seen_train = {lab for lab, n in aoc_cli.info("a", store=store)["tags"]["hospital"].items()
                  if n}
    seen_test = {lab for lab, n in aoc_cli.info("b", store=store)["tags"]["hospital"].items()
                 if n}
    assert seen_train and seen_test and not seen_train & seen_test
    assert test.preprocessing["split"]["by"] == "hospital"
    assert train.n_episodes + test.n_episodes == 50


def test_split_command_prints_both_parts_and_refuses_bad_shares(cohort_store, aoc_inproc):
    store, _cols = cohort_store
    code, out, err = aoc_inproc("--store", str(store.root), "split", "icu", "--test", "0.25",
                                "--seed", "2", "--format", "json")
    assert code == 0, err
    rows = json.loads(out)
    assert [r["part"] for r in rows] == ["train", "test"] and rows[1]["episodes"] == 12
    code, _out, err = aoc_inproc("--store", str(store.root), "split", "icu", "--test", "1.5",
                                 "--overwrite")
    assert code == 2 and "--test 1.5 must be a share" in err and len(err.splitlines()) == 1
    with pytest.raises(AocError, match="no tag 'ward'"):
        aoc_cli.split("icu", by="ward", store=store, overwrite=True)
