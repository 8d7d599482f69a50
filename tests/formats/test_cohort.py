"""A clinical cohort table (scripts/cohort.py) through ingest: gaps filled by the user's rule
and counted, outcomes as rewards, dose bins, censored stays; fitted statistics reused, never
refitted on held-out data."""

import numpy as np
import pytest

import aoc_cli
from aoc_cli.errors import AocError
from aoc_cli.formats import ReadOptions, read_dataset
from aoc_cli.store import Store
from tests.formats.cohorts import OBS, cohort, roles, script, write

DOSES = "input_4hourly=5,max_dose_vaso=5"


def _read(cols, tmp_path, **extra):
    path = write(cols, tmp_path / "c.csv")
    return read_dataset(path, options=ReadOptions(**roles(**{"act_columns": ["input_4hourly"],
                                                             **extra})))


def test_gaps_are_refused_naming_the_worst_columns_and_the_flags(tmp_path):
    cols = cohort()
    with pytest.raises(AocError, match=r"observation columns have empty cells \(worst: "
                                       r"'\w+' \d+\.\d%.*impute.*drop_nonfinite"):
        _read(cols, tmp_path)


@pytest.mark.parametrize("rule", ["hold", "median"])
def test_impute_fills_every_gap_by_its_rule_and_counts_each_cell(tmp_path, rule):
    cols = cohort()
    data = _read(cols, tmp_path, impute=rule)
    raw = np.stack([cols[c] for c in OBS], axis=1)
    empty = np.isnan(raw)
    np.testing.assert_array_equal(data.imputed, empty)
    medians = np.nanmedian(raw, axis=0)
    assert data.preprocessing["impute"]["medians"] == pytest.approx(medians.tolist())
    stay = np.repeat(np.arange(data.n_episodes), np.diff(data.episode_starts))
    for j in range(raw.shape[1]):
        for r in np.flatnonzero(empty[:, j])[:40]:
            before = [i for i in range(r - 1, -1, -1) if stay[i] == stay[r] and not empty[i, j]]
            expect = raw[before[0], j] if rule == "hold" and before else medians[j]
            assert data.observations[r, j] == expect
    assert np.array_equal(data.observations[~empty], raw[~empty])


def test_measured_features_are_named_and_ingest_and_info_count_the_cells(tmp_path):
    cols = cohort()
    store = Store(tmp_path / "s")
    path = write(cols, tmp_path / "c.csv")
    result = aoc_cli.ingest(path, "icu", store=store, options=roles(
        act_columns=["input_4hourly"], impute="hold", impute_mask=True))
    c = store.corpus("icu")
    names = c.observation_space["names"]
    gaps = [n for n in OBS if np.isnan(cols[n]).any()]
    assert names == OBS + [f"{n}?measured" for n in gaps]
    j = names.index(f"{gaps[0]}?measured")
    np.testing.assert_array_equal(c.observations[:, j], ~np.isnan(cols[gaps[0]]))
    expect = {n: int(np.isnan(cols[n]).sum()) for n in gaps}
    assert result.summary()["imputed_cells"] == expect
    info = aoc_cli.info("icu", store=store)
    assert info["imputed_cells"] == expect and info["preprocessing"]["impute"]["mask"]
    assert c.imputed_mask.shape == c.observations.shape and c.imputed_mask[:, j].sum() == 0


def test_held_out_and_appended_stays_are_filled_with_the_corpus_medians(tmp_path):
    store = Store(tmp_path / "s")
    train = write(cohort(seed=0), tmp_path / "train.csv")
    held_cols = cohort(seed=1)
    for c in OBS[2:]:  # held-out values far from the training ones: their own medians differ
        held_cols[c] = held_cols[c] + 1000.0
    held = write(held_cols, tmp_path / "held.csv")
    opts = roles(act_columns=["input_4hourly"])
    aoc_cli.ingest(train, "icu", store=store, options={**opts, "impute": "median"})
    medians = store.corpus("icu").preprocessing["impute"]["medians"]
    aoc_cli.ingest(held, "held", store=store, options={**opts, "impute_like": "icu"})
    h = store.corpus("held")
    raw = np.stack([held_cols[c] for c in OBS], axis=1)
    empty = np.isnan(raw)
    filled = np.broadcast_to(medians, raw.shape)[empty]
    np.testing.assert_array_equal(h.observations[empty], filled)
    assert h.preprocessing["impute"]["medians"] == medians
    assert h.preprocessing["like"] == {"impute": "icu"}
    n0 = store.corpus("icu").n_rows
    aoc_cli.ingest(held, "icu", store=store, options=opts, append=True)
    c = store.corpus("icu")
    np.testing.assert_array_equal(c.observations[n0:][empty], filled)
    assert c.preprocessing["impute"]["medians"] == medians
    assert c.imputed_mask[n0:].sum() == empty.sum()
    aoc_cli.ingest(write(cohort(gap=0.0), tmp_path / "full.csv"), "plain", store=store,
                   options=opts)
    with pytest.raises(AocError, match="corpus 'plain' has no imputation to reuse"):
        aoc_cli.ingest(held, "y", store=store, options={**opts, "impute_like": "plain"})


def test_the_outcome_is_the_last_reward_and_an_empty_outcome_censors_the_stay(tmp_path):
    cols = cohort(stays=60, censored=0.1, gap=0.0)
    data = _read(cols, tmp_path, outcome="died_in_hosp", outcome_reward="1=-1,0=1")
    starts = data.episode_starts
    last = starts[1:] - 1
    died = cols["died_in_hosp"][last]
    cut = np.isnan(died)
    assert cut.any() and (~cut).any()
    np.testing.assert_array_equal(data.rewards[last[~cut]], np.where(died[~cut] == 1, -1, 1))
    assert np.count_nonzero(data.rewards) == (~cut).sum()
    np.testing.assert_array_equal(data.truncations[last], cut)
    np.testing.assert_array_equal(data.terminals[last], ~cut)


def test_the_censoring_column_marks_a_stay_truncated(tmp_path):
    cols = cohort(stays=8, censored=0.0, gap=0.0)
    cols["transferred"] = np.zeros(len(cols["bloc"]))
    cols["transferred"][cols["icustayid"] == cols["icustayid"][0]] = 1
    data = _read(cols, tmp_path, censored_column="transferred", outcome="died_in_hosp",
                 outcome_reward="1=-1,0=1")
    last = data.episode_starts[1:] - 1
    assert data.truncations[last].tolist() == [True] + [False] * 7
    assert not data.terminals[last[0]] and "transferred" not in data.columns


def test_doses_are_cut_into_labelled_bins_at_their_quantiles(tmp_path):
    cols = cohort(stays=60, gap=0.0)
    data = _read(cols, tmp_path, act_columns=None, bin_actions=DOSES)
    fluid, vaso = cols["input_4hourly"], cols["max_dose_vaso"]
    assert data.action_space["n"] == 25 and data.discrete
    spec = data.preprocessing["bins"]
    for col, dose in (("input_4hourly", fluid), ("max_dose_vaso", vaso)):
        nz = dose[dose > 0]
        assert spec["edges"][col] == pytest.approx(
            [nz.min(), *np.quantile(nz, [0.25, 0.5, 0.75]), nz.max()])
    level_f, level_v = data.actions // 5, data.actions % 5
    np.testing.assert_array_equal(level_f == 0, fluid == 0)
    np.testing.assert_array_equal(level_v == 0, vaso == 0)
    counts = np.bincount(level_f[fluid > 0], minlength=5)[1:]
    assert counts.min() >= 0.2 * (fluid > 0).sum()  # quartiles: about a quarter each
    label = data.action_space["names"][int(data.actions[np.argmax(fluid)])]
    assert label.startswith("input_4hourly 4/5 (") and ", max_dose_vaso " in label
    assert data.action_space["names"][0] == "input_4hourly 0/5 (0), max_dose_vaso 0/5 (0)"
    np.testing.assert_array_equal(data.columns["input_4hourly"], fluid)  # raw doses kept


def test_bin_like_and_append_reuse_the_edges(tmp_path):
    store = Store(tmp_path / "s")
    opts = roles(bin_actions=DOSES)
    aoc_cli.ingest(write(cohort(seed=0, gap=0.0), tmp_path / "a.csv"), "icu", store=store,
                   options=opts)
    edges = store.corpus("icu").preprocessing["bins"]
    other = cohort(seed=1, gap=0.0)
    other["input_4hourly"] = other["input_4hourly"] * 3  # its own quantiles would differ
    path = write(other, tmp_path / "b.csv")
    aoc_cli.ingest(path, "held", store=store, options={**roles(), "bin_like": "icu"})
    assert store.corpus("held").preprocessing["bins"] == edges
    aoc_cli.ingest(path, "icu", store=store, options=roles(), append=True)
    c = store.corpus("icu")
    assert c.preprocessing["bins"] == edges
    np.testing.assert_array_equal(c.actions[-len(other["bloc"]):], store.corpus("held").actions)


@pytest.mark.parametrize("damage, extra, message", [
    ("duplicate", {}, r"data rows \d+ and \d+ are both at \(icustayid 200000, bloc 1\)"),
    ("negative", {"bin_actions": DOSES}, r"dose column 'max_dose_vaso', data row 3 "
                                          r"\(icustayid 200000\) holds -0.5, a negative dose"),
    ("outcome", {"outcome": "died_in_hosp", "outcome_reward": "1=-1,0=1"},
     r"outcome 'died_in_hosp' changes within a stay: data row 2 \(icustayid 200000\)"),
    ("text", {"bin_actions": DOSES}, r"column 'input_4hourly', data row 4 \(icustayid 200000\) "
                                     r"holds 'high', not a number"),
    ("text", {"act_columns": ["input_4hourly"]}, r"column 'input_4hourly' mixes numbers and text "
                                                r"\(data row 4 \(icustayid 200000\) holds"),
    ("few", {"bin_actions": "input_4hourly=5,max_dose_vaso=5"},
     r"needs at least 4 distinct non-zero doses of 'max_dose_vaso'.* the data hold 2"),
    ("empty", {"impute": "median"}, r"column 'HR' is empty for every stay"),
])
def test_bad_cohort_input_is_one_line_naming_row_and_stay(tmp_path, damage, extra, message):
    cols = {k: v.astype(object) for k, v in cohort(stays=4, gap=0.0).items()}
    if damage == "duplicate":
        cols = {k: np.concatenate([v, v[:1]]) for k, v in cols.items()}
    elif damage == "negative":
        cols["max_dose_vaso"][2] = -0.5
    elif damage == "outcome":
        cols["died_in_hosp"][1] = 1 - cols["died_in_hosp"][0]
    elif damage == "text":
        cols["input_4hourly"][3] = "high"
    elif damage == "few":
        cols["max_dose_vaso"] = np.where(np.arange(len(cols["bloc"])) % 2, 0.5, 0.0)
        cols["max_dose_vaso"][1] = 0.25
    elif damage == "empty":
        cols["HR"] = np.full(len(cols["bloc"]), np.nan)
    path = tmp_path / "c.csv"
    lines = [",".join(cols)] + [",".join("" if isinstance(v, float) and np.isnan(v) else str(v)
                                          for v in row) for row in zip(*cols.values())]
    path.write_text("\n".join(lines) + "\n")
    opts = roles(**{"act_columns": ["input_4hourly"], **extra})
    if "bin_actions" in extra:
        opts.pop("act_columns")
    with pytest.raises(AocError, match=message):
        read_dataset(path, options=ReadOptions(**opts))


def test_the_generator_cohort_keeps_at_least_99_percent_of_its_stays(tmp_path):
    cols = cohort(stays=100)
    data = _read(cols, tmp_path, act_columns=None, bin_actions=DOSES, impute="hold",
                 outcome="died_in_hosp", outcome_reward="1=-1,0=1")
    assert data.n_episodes == 100 and data.n_rows == len(cols["bloc"])
    assert np.isfinite(data.observations).all() and np.isfinite(data.rewards).all()
    assert script.cohort(5, 0)["icustayid"].dtype.kind == "i"


def test_the_table_flags_are_refused_on_other_formats(tmp_path):
    from tests.formats.sources import flat_arrays

    path = tmp_path / "x.npz"
    np.savez(path, **{k: v for k, v in flat_arrays()[0].items() if v is not None})
    with pytest.raises(AocError, match="applies to tables"):
        read_dataset(path, options=ReadOptions(impute="median"))


def test_a_study_s_dose_levels_given_as_a_dict_cut_the_doses_at_them(tmp_path):
    cols = cohort(stays=20, gap=0.0)
    data = _read(cols, tmp_path, act_columns=None,
                 bin_actions={"input_4hourly": [0, 50, 180, 530], "max_dose_vaso": 3})
    spec = data.preprocessing["bins"]
    assert spec["edges"]["input_4hourly"] == [0.0, 50.0, 180.0, 530.0, None]
    assert spec["given"] == ["input_4hourly"] and spec["bins"] == [5, 3]
    fluid = cols["input_4hourly"]
    level = np.select([fluid >= 530, fluid >= 180, fluid >= 50, fluid > 0], [4, 3, 2, 1], 0)
    np.testing.assert_array_equal(data.actions // 3, level)
    with pytest.raises(AocError, match=r"bin_actions='input_4hourly=\[0, 50, 40\]': the dose "
                                       r"levels of 'input_4hourly' do not increase \(50 then 40"):
        _read(cols, tmp_path, act_columns=None, bin_actions={"input_4hourly": [0, 50, 40]})


def test_the_outcome_among_the_observations_is_refused_by_the_library_too(tmp_path):
    from aoc_cli.errors import RoleOverlap

    cols = cohort(stays=6, gap=0.0, censored=0.0)
    extra = dict(obs_columns=[*OBS, "died_in_hosp"], outcome="died_in_hosp",
                 outcome_reward="1=-1,0=1")
    with pytest.raises(RoleOverlap, match=r"column 'died_in_hosp' is the outcome \(outcome\) "
                                          r"and an observation \(obs_columns\): the outcome "
                                          r"would leak.*allow_role_overlap=True") as err:
        _read(cols, tmp_path, **extra)
    assert (err.value.column, err.value.role) == ("died_in_hosp", "outcome")
    data = _read(cols, tmp_path, allow_role_overlap=True, **extra)
    assert data.observation_space["names"][-1] == "died_in_hosp"
    j = len(OBS)
    last = data.episode_starts[1:] - 1
    np.testing.assert_array_equal(data.observations[last, j], cols["died_in_hosp"][last])


def test_a_mapping_s_observations_are_checked_and_static_role_columns_left_out(tmp_path):
    import json

    from aoc_cli.errors import RoleOverlap

    cols = cohort(stays=6, gap=0.0, censored=0.0)
    path = write(cols, tmp_path / "c.csv")
    mapping = tmp_path / "roles.json"
    mapping.write_text(json.dumps({"id": "icustayid", "time": "bloc",
                                   "observations": ["HR", "bloc"],
                                   "actions": ["input_4hourly"]}))
    with pytest.raises(RoleOverlap, match=r"column 'bloc' is the time \(time_column\) and an "
                                          r"observation \(the observations of columns_file\)"):
        read_dataset(path, options=ReadOptions(columns_file=mapping))
    # a static table holding the outcome too: not a feature (it would leak), unless allowed
    ids = np.unique(cols["icustayid"])
    static = tmp_path / "static.csv"
    died = {i: cols["died_in_hosp"][cols["icustayid"] == i][0] for i in ids}
    static.write_text("icustayid,weight,died_in_hosp\n" + "".join(
        f"{i},{70 + k},{died[i]:g}\n" for k, i in enumerate(ids)))
    opts = roles(act_columns=["input_4hourly"], static=static, outcome="died_in_hosp",
                 outcome_reward="1=-1,0=1")
    data = read_dataset(path, options=ReadOptions(**opts))
    assert data.observation_space["static"] == ["weight"]
    data = read_dataset(path, options=ReadOptions(**opts, allow_role_overlap=True))
    assert data.observation_space["static"] == ["weight", "died_in_hosp"]
