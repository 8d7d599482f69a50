"""A clinical corpus (scripts/cohort.py: gaps filled, doses binned, outcome as reward, censored
stays) exported and ingested back keeps what it was prepared with: the imputed-cell mask and
the preprocessing (rule, medians, bin edges), in every export format."""

import numpy as np
import pytest

import aoc_cli
from aoc_cli.errors import AocError
from aoc_cli.formats import export, ingest
from aoc_cli.formats.spec import pack_mask, unpack_mask
from aoc_cli.store import Store
from tests.formats.cohorts import cohort, roles, write

SUFFIX = {"minari": "", "d4rl": ".hdf5", "csv": ".csv"}


@pytest.fixture(scope="module")
def clinical(tmp_path_factory):
    root = tmp_path_factory.mktemp("export-cohort")
    mp = pytest.MonkeyPatch()
    mp.setenv("MINARI_DATASETS_PATH", str(root / "minari"))
    store = Store(root / "store")
    path = write(cohort(30, seed=3, censored=0.1), root / "c.csv")
    aoc_cli.ingest(path, "icu", store=store, options=roles(
        impute="hold", impute_mask=True, bin_actions="input_4hourly=3,max_dose_vaso=3",
        outcome="died_in_hosp", outcome_reward="1=-1,0=1"))
    yield store, root
    mp.undo()


@pytest.mark.parametrize("fmt", ["csv", "d4rl", "minari"])
def test_an_export_read_back_keeps_the_imputed_mask_and_preprocessing(clinical, fmt):
    store, root = clinical
    c = store.corpus("icu")
    mask = c.imputed_mask
    assert mask is not None and mask.any() and set(c.preprocessing) >= {"impute", "bins",
                                                                         "outcome"}
    out = root / "out" / f"icu{SUFFIX[fmt]}"
    export("icu", fmt, out, store=store, overwrite=True)
    ingest(out, f"icu-{fmt}", store=store, overwrite=True)
    back = store.corpus(f"icu-{fmt}")
    assert back.hash == c.hash
    np.testing.assert_array_equal(back.imputed_mask, mask)
    assert back.preprocessing == c.preprocessing
    assert aoc_cli.info(f"icu-{fmt}", store=store).get("imputed_cells") == \
        aoc_cli.info("icu", store=store).get("imputed_cells")


def test_a_row_selection_exports_the_mask_of_its_rows(clinical):
    store, root = clinical
    c = store.corpus("icu")
    a, b = int(c.episode_starts[2]), int(c.episode_starts[5])
    out = root / "out" / "part.hdf5"
    export("icu", "d4rl", out, store=store, overwrite=True, rows=(a, b))
    ingest(out, "icu-part", store=store, overwrite=True)
    back = store.corpus("icu-part")
    np.testing.assert_array_equal(back.imputed_mask, c.imputed_mask[a:b])
    assert back.preprocessing["impute"] == c.preprocessing["impute"]


def test_data_ingested_like_a_read_back_corpus_use_its_medians(clinical, tmp_path):
    store, root = clinical
    export("icu", "csv", root / "out" / "like.csv", store=store, overwrite=True)
    ingest(root / "out" / "like.csv", "icu-like-src", store=store, overwrite=True)
    held = write(cohort(10, seed=9), tmp_path / "held.csv")
    aoc_cli.ingest(held, "held", store=store, options=roles(
        impute_like="icu-like-src", bin_like="icu-like-src", outcome="died_in_hosp",
        outcome_reward="1=-1,0=1"))
    h = store.corpus("held")
    assert h.preprocessing["impute"]["medians"] == \
        store.corpus("icu").preprocessing["impute"]["medians"]
    assert h.preprocessing["like"] == {"impute": "icu-like-src", "bins": "icu-like-src"}


def test_a_mask_that_does_not_fit_is_one_clear_error():
    mask = np.random.default_rng(0).random((7, 3)) < 0.3
    np.testing.assert_array_equal(unpack_mask(pack_mask(mask), (7, 3), "f"), mask)
    for shape in ((7, 4), (6, 3)):
        with pytest.raises(AocError, match="imputed-cell mask .* re-export"):
            unpack_mask(pack_mask(mask), shape, "f")
    with pytest.raises(AocError, match="re-export"):
        unpack_mask({"shape": [7, 3], "bits": "not base64 zlib"}, (7, 3), "f")
