"""``aoc ingest`` through the real CLI: the summary, and every bad input of issue 2 (one line
on stderr, exit 2, the store untouched)."""

import hashlib
import json
import os

import h5py
import numpy as np
import pytest

from tests.conftest import run_in_process

from tests.formats.sources import flat_arrays, write_csv, write_d4rl


def snapshot(root):
    """Every file under the store with its content hash (and every folder, incl. temporaries);
    not the writer lock files ``.NAME.lock`` (a pid, no data; those of existing corpora stay)."""
    out = {}
    if not os.path.exists(root):
        return out
    for dirpath, dirnames, filenames in os.walk(root):
        for d in dirnames:
            out[os.path.relpath(os.path.join(dirpath, d), root)] = "dir"
        for f in filenames:
            if f.startswith(".") and f.endswith(".lock"):
                continue
            p = os.path.join(dirpath, f)
            out[os.path.relpath(p, root)] = hashlib.md5(open(p, "rb").read()).hexdigest()
    return out


@pytest.fixture
def aoc(capsys):
    """Overrides the subprocess runner of tests/conftest.py for speed (see run_in_process)."""
    return lambda *args: run_in_process(capsys, *args)


def test_real_process_exit_codes_and_one_line_errors(store, d4rl_file):
    from tests.conftest import run_aoc

    code, out, err = run_aoc("ingest", str(d4rl_file), "--name", "hopper", "-f", "json")
    assert code == 0 and json.loads(out)["rows"] == 400, err
    code, out, err = run_aoc("ingest", str(d4rl_file), "--name", "hopper")
    assert code == 2 and out == ""
    assert err.strip().splitlines() == [
        "aoc: error: corpus 'hopper' already exists: pass --overwrite to replace it or "
        "--append to add to it"]


@pytest.fixture
def d4rl_file(tmp_path):
    arrays, _ = flat_arrays()
    return write_d4rl(tmp_path / "hopper.hdf5", arrays)


@pytest.fixture
def filled_store(store, aoc, d4rl_file):
    code, _, err = aoc("ingest", str(d4rl_file), "--name", "hopper")
    assert code == 0, err
    return store


def assert_refused(aoc, store, args, match):
    before = snapshot(store)
    code, out, err = aoc(*args)
    assert code == 2, (out, err)
    assert out == ""
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("aoc: error:"), err
    assert match in lines[0], lines[0]
    assert snapshot(store) == before
    return lines[0]


def test_ingest_prints_summary_in_the_requested_format(store, aoc, d4rl_file):
    code, out, err = aoc("ingest", str(d4rl_file), "--name", "hopper", "--format", "json")
    assert code == 0, err
    summary = json.loads(out)
    assert {k: summary[k] for k in ("name", "rows", "episodes", "format")} == \
        {"name": "hopper", "rows": 400, "episodes": 4, "format": "d4rl"}
    assert summary["seconds"] >= 0
    code, out, _ = aoc("ingest", str(d4rl_file), "--name", "h2", "--format", "csv")
    assert out.splitlines()[0].startswith("name,format,rows,episodes,seconds")
    assert out.splitlines()[1].startswith("h2,d4rl,400,4,")


def test_append_adds_episodes_and_overwrite_replaces(filled_store, aoc, d4rl_file):
    code, out, err = aoc("ingest", str(d4rl_file), "--name", "hopper", "--append", "-f", "json")
    assert code == 0, err
    summary = json.loads(out)
    assert summary["rows"] == 400 and summary["total_rows"] == 800
    assert summary["total_episodes"] == 8
    code, out, err = aoc("ingest", str(d4rl_file), "--name", "hopper", "--overwrite",
                         "-f", "json")
    assert code == 0 and json.loads(out)["rows"] == 400


def test_forced_format_and_csv_options_reach_the_reader(store, aoc, tmp_path):
    path = write_csv(tmp_path / "log.txt", ["pid", "hour", "hr", "treat", "group"],
                     [[1, 0, 80.0, 1, "a"], [1, 1, 82.0, 0, "a"], [2, 0, 90.0, 1, "b"]])
    code, out, err = aoc("ingest", str(path), "--name", "icu", "--from", "csv",
                         "--id-column", "pid", "--time-column", "hour", "--obs-columns", "hr",
                         "--act-columns", "treat", "--discrete-actions", "--reward-free",
                         "--tag-column", "group", "--tag", "site=x", "-f", "json")
    assert code == 0, err
    code, out, _ = aoc("info", "icu", "-f", "json")
    info = json.loads(out)
    assert info["discrete"] and not info["has_rewards"] and info["episodes"] == 2
    assert info["tags"] == {"group": {"a": 2, "b": 1}, "site": {"x": 3}}


def test_missing_path(store, aoc, tmp_path):
    assert_refused(aoc, store, ["ingest", str(tmp_path / "nope.hdf5"), "--name", "x"],
                   "no such file or folder")


def test_unknown_format(store, aoc, tmp_path):
    (tmp_path / "notes.txt").write_text("hello\n")
    assert_refused(aoc, store, ["ingest", str(tmp_path / "notes.txt"), "--name", "x"],
                   "cannot tell the format")
    assert_refused(aoc, store, ["ingest", str(tmp_path / "notes.txt"), "--name", "x",
                                "--from", "xlsx"], "unknown format 'xlsx'")


def test_undetectable_hdf5(store, aoc, tmp_path):
    with h5py.File(tmp_path / "other.h5", "w") as f:
        f["weights"] = np.zeros(3)
    assert_refused(aoc, store, ["ingest", str(tmp_path / "other.h5"), "--name", "x"],
                   "cannot tell the format of HDF5 file")


def test_truncated_hdf5(store, aoc, d4rl_file):
    data = d4rl_file.read_bytes()
    d4rl_file.write_bytes(data[: len(data) // 2])
    assert_refused(aoc, store, ["ingest", str(d4rl_file), "--name", "x"], "truncated or corrupt")


def test_corrupt_hdf5(store, aoc, d4rl_file):
    data = bytearray(d4rl_file.read_bytes())
    data[8:4096] = os.urandom(4088)  # keep the signature, destroy the superblock and tree
    d4rl_file.write_bytes(bytes(data))
    assert_refused(aoc, store, ["ingest", str(d4rl_file), "--name", "x", "--from", "d4rl"],
                   "truncated or corrupt")


def test_arrays_of_different_lengths(store, aoc, tmp_path):
    arrays, _ = flat_arrays()
    arrays["actions"] = arrays["actions"][:-3]
    path = write_d4rl(tmp_path / "bad.hdf5", arrays)
    line = assert_refused(aoc, store, ["ingest", str(path), "--name", "x"],
                          "arrays of different lengths")
    assert "actions has 397 rows" in line


def test_nonfinite_values_name_the_first_bad_row(store, aoc, tmp_path):
    arrays, _ = flat_arrays()
    arrays["rewards"][170] = np.inf
    arrays["observations"][160, 2] = np.nan
    path = write_d4rl(tmp_path / "nan.hdf5", arrays)
    line = assert_refused(aoc, store, ["ingest", str(path), "--name", "x"], "row 160")
    assert "observations" in line and "episode 2" in line and "step 10" in line
    assert "--drop-nonfinite" in line


def test_drop_nonfinite_drops_those_episodes(store, aoc, tmp_path):
    arrays, _ = flat_arrays()
    arrays["observations"][160, 2] = np.nan  # episode 2 (rows 150..299)
    path = write_d4rl(tmp_path / "nan.hdf5", arrays)
    code, out, err = aoc("ingest", str(path), "--name", "x", "--drop-nonfinite", "-f", "json")
    assert code == 0, err
    summary = json.loads(out)
    assert summary["rows"] == 250 and summary["episodes"] == 3
    assert summary["dropped_episodes"] == 1


def test_zero_rows(store, aoc, tmp_path):
    arrays, _ = flat_arrays()
    empty = {k: v[:0] for k, v in arrays.items()}
    path = write_d4rl(tmp_path / "empty.hdf5", empty)
    assert_refused(aoc, store, ["ingest", str(path), "--name", "x"], "zero rows")
    csv_path = write_csv(tmp_path / "empty.csv", ["episode", "t", "obs_a", "act_u"], [])
    assert_refused(aoc, store, ["ingest", str(csv_path), "--name", "x"], "zero rows")


def test_existing_name_without_overwrite(filled_store, aoc, d4rl_file):
    assert_refused(aoc, filled_store, ["ingest", str(d4rl_file), "--name", "hopper"],
                   "already exists: pass --overwrite")


def test_append_with_different_spaces(filled_store, aoc, tmp_path):
    arrays, _ = flat_arrays(d_o=7)
    path = write_d4rl(tmp_path / "other.hdf5", arrays)
    assert_refused(aoc, filled_store, ["ingest", str(path), "--name", "hopper", "--append"],
                   "cannot --append to 'hopper'")


@pytest.mark.parametrize("name", ["../escape", "a/b", "..", ".hidden"])
def test_invalid_corpus_name(filled_store, aoc, d4rl_file, name):
    assert_refused(aoc, filled_store, ["ingest", str(d4rl_file), "--name", name],
                   "invalid corpus name")
    assert not (filled_store.parent / "escape").exists()


# --- a cohort table: a study's own dose levels, no column in two roles -------------------------

FLUID_EDGES = [0.0, 50.0, 180.0, 530.0]  # the AI Clinician's MIMIC-III fluid levels
VASO_EDGES = [0.0, 0.08, 0.22, 0.45]


def _cohort_csv(tmp_path, name="c.csv", seed=0, **extra_cols):
    from tests.formats.cohorts import cohort, write

    cols = cohort(stays=30, seed=seed, gap=0.0, censored=0.0)
    cols.update(extra_cols)
    return cols, write(cols, tmp_path / name)


def _role_flags(*obs_extra):
    from tests.formats.cohorts import OBS

    return ["--id-column", "icustayid", "--time-column", "bloc",
            "--obs-columns", ",".join([*OBS, *obs_extra])]


def _levels(dose, edges):
    return np.where(dose > 0, np.searchsorted(edges[1:], dose, side="right") + 1, 0)


def test_given_dose_levels_are_stored_and_reused_by_bin_like_and_split(store, aoc, tmp_path):
    cols, path = _cohort_csv(tmp_path)
    spec = (f"input_4hourly={':'.join(f'{x:g}' for x in FLUID_EDGES)},"
            f"max_dose_vaso={':'.join(f'{x:g}' for x in VASO_EDGES)}")
    code, _, err = aoc("ingest", str(path), "--name", "icu", *_role_flags(),
                       "--bin-actions", spec)
    assert code == 0, err
    from aoc_cli.store import Store

    s = Store(store)
    bins = s.corpus("icu").preprocessing["bins"]
    assert bins["edges"] == {"input_4hourly": [*FLUID_EDGES, None],
                             "max_dose_vaso": [*VASO_EDGES, None]}
    assert bins["bins"] == [5, 5] and bins["given"] == ["input_4hourly", "max_dose_vaso"]

    def expected(cols):
        return (_levels(cols["input_4hourly"], FLUID_EDGES) * 5 +
                _levels(cols["max_dose_vaso"], VASO_EDGES))

    data = s.corpus("icu").load()
    np.testing.assert_array_equal(data.actions, expected(cols))  # cohort rows in stay order
    names = data.action_space["names"]
    assert names[5 * 4 + 1] == "input_4hourly 4/5 (530+), max_dose_vaso 1/5 (0-0.08)"
    code, out, _ = aoc("info", "icu", "-f", "table")
    assert "dose bins input_4hourly=0:50:180:530,max_dose_vaso=0:0.08:0.22:0.45" in out
    # a second file, whose own quantiles differ: cut at the given levels all the same
    other, path_b = _cohort_csv(tmp_path, "b.csv", seed=1)
    other["input_4hourly"] *= 3
    from tests.formats.cohorts import write

    write(other, path_b)
    code, _, err = aoc("ingest", str(path_b), "--name", "held", *_role_flags(),
                       "--bin-like", "icu")
    assert code == 0, err
    held = s.corpus("held")
    assert held.preprocessing["bins"] == bins
    np.testing.assert_array_equal(held.load().actions, expected(other))
    # the same edges again: accepted; other ones: refused
    code, _, err = aoc("ingest", str(path_b), "--name", "held2", *_role_flags(),
                       "--bin-like", "icu", "--bin-actions", spec)
    assert code == 0, err
    line = assert_refused(aoc, store, ["ingest", str(path_b), "--name", "held3",
                                       *_role_flags(), "--bin-like", "icu", "--bin-actions",
                                       "input_4hourly=5,max_dose_vaso=0:0.08:0.22:0.45"],
                          "--bin-actions differs from the bins of corpus 'icu'")
    assert "(input_4hourly=0:50:180:530,max_dose_vaso=0:0.08:0.22:0.45)" in line
    # aoc split keeps the given edges (nothing to fit) and cuts both parts at them
    code, _, err = aoc("split", "icu", "--test", "0.3", "--seed", "0")
    assert code == 0, err
    for part in ("icu-train", "icu-test"):
        c = s.corpus(part)
        assert c.preprocessing["bins"] == bins
        d = c.load()
        np.testing.assert_array_equal(d.actions, expected(d.columns))


def test_given_dose_levels_mixed_with_a_count_refit_only_the_count_on_split(store, aoc,
                                                                             tmp_path):
    cols, path = _cohort_csv(tmp_path)
    code, _, err = aoc("ingest", str(path), "--name", "icu", *_role_flags(),
                       "--bin-actions", "input_4hourly=0:50:180:530,max_dose_vaso=3")
    assert code == 0, err
    code, _, err = aoc("split", "icu", "--test", "0.3", "--seed", "0")
    assert code == 0, err
    from aoc_cli.store import Store

    train = Store(store).corpus("icu-train")
    bins = train.preprocessing["bins"]
    assert bins["given"] == ["input_4hourly"] and bins["bins"] == [5, 3]
    assert bins["edges"]["input_4hourly"] == [*FLUID_EDGES, None]
    vaso = train.load().columns["max_dose_vaso"]
    nz = vaso[vaso > 0]
    assert bins["edges"]["max_dose_vaso"] == pytest.approx([nz.min(), np.median(nz), nz.max()])


@pytest.mark.parametrize("value, message", [
    ("0:180:50", "the dose levels of 'input_4hourly' do not increase (180 then 50)"),
    ("0:50:50", "the dose levels of 'input_4hourly' do not increase (50 then 50)"),
    ("-10:50:180", "the dose levels of 'input_4hourly' start at -10, a negative dose"),
    ("0:fifty:180", "the dose levels of 'input_4hourly' hold 'fifty', not a number"),
    ("0:50:", "the dose levels of 'input_4hourly' hold '', not a number"),
    ("0:nan", "the dose levels of 'input_4hourly' hold 'nan', not a number"),
    ("1", "write COLUMN=BINS (BINS >= 2"),
])
def test_bad_dose_levels_are_one_line_naming_the_column(store, aoc, tmp_path, value, message):
    _, path = _cohort_csv(tmp_path)
    line = assert_refused(aoc, store, ["ingest", str(path), "--name", "icu", *_role_flags(),
                                       "--bin-actions", f"input_4hourly={value}"], message)
    assert f"--bin-actions input_4hourly={value}" in line
    assert "0:50:180:530" in line or "0:0.08:0.22:0.45" in line  # what to give


#: (the role's flags, the column, what the error names it)
OVERLAPS = {
    "outcome": (["--outcome", "died_in_hosp", "--outcome-reward", "1=-1,0=1"], "died_in_hosp",
                "is the outcome (--outcome)", "the outcome would leak into the state"),
    "reward": (["--reward-column", "mortality_90d"], "mortality_90d",
               "is the reward (--reward-column)", "the reward would leak into the state"),
    "action": (["--act-columns", "input_4hourly"], "input_4hourly",
               "is an action (--act-columns)", "the action would leak"),
    "binned action": (["--bin-actions", "input_4hourly=3"], "input_4hourly",
                      "is an action (--bin-actions)", "the action would leak"),
    "censoring": (["--censored-column", "transferred"], "transferred",
                  "is the censoring flag (--censored-column)", "the censoring would leak"),
    "stay id": ([], "icustayid", "is the stay id (--id-column)",
                "the stay's id would become a feature"),
    "time": ([], "bloc", "is the time (--time-column)", "the time would become a feature"),
    "terminal": (["--terminal-column", "ended"], "ended",
                 "is the terminal flag (--terminal-column)", "the stay's end would leak"),
}


@pytest.mark.parametrize("case", sorted(OVERLAPS))
def test_a_role_column_among_the_observations_is_refused_unless_allowed(store, aoc, tmp_path,
                                                                         case):
    flags, column, role, harm = OVERLAPS[case]
    cols, path = _cohort_csv(tmp_path)
    n = len(cols["bloc"])
    ends = np.zeros(n)
    ends[np.r_[cols["icustayid"][1:] != cols["icustayid"][:-1], True]] = 1
    from tests.formats.cohorts import write

    write({**cols, "transferred": np.zeros(n), "ended": ends}, path)
    act = [] if "--act-columns" in flags or "--bin-actions" in flags else \
        ["--act-columns", "max_dose_vaso"]
    args = ["ingest", str(path), "--name", "icu", *_role_flags(column), *act, *flags]
    line = assert_refused(aoc, store, args, f"column {column!r} {role} and an observation "
                                            "(--obs-columns)")
    assert harm in line
    assert line.endswith("drop it from the observations, or pass --allow-role-overlap")
    code, out, err = aoc(*args, "--allow-role-overlap", "-f", "json")
    assert code == 0, err
    code, out, _ = aoc("info", "icu", "-f", "json")
    assert column in json.loads(out)["observation_space"]["names"]


def test_default_observations_leave_out_role_columns(store, aoc, tmp_path):
    """No --obs-columns: the obs_* columns are the observations, a role column among them
    left out (not refused); --allow-role-overlap keeps it."""
    rng = np.random.default_rng(0)
    rows = [[e, t, *np.round(rng.normal(size=2), 3), e % 2, int(t == 2)]
            for e in range(4) for t in range(3)]
    path = write_csv(tmp_path / "log.csv", ["episode", "t", "obs_hr", "obs_sbp", "act_0",
                                            "obs_died"], rows)
    code, _, err = aoc("ingest", str(path), "--name", "a", "--reward-column", "obs_died")
    assert code == 0, err
    code, out, _ = aoc("info", "a", "-f", "json")
    assert json.loads(out)["observation_space"]["names"] == ["obs_hr", "obs_sbp"]
    code, _, err = aoc("ingest", str(path), "--name", "b", "--reward-column", "obs_died",
                       "--allow-role-overlap")
    assert code == 0, err
    code, out, _ = aoc("info", "b", "-f", "json")
    assert json.loads(out)["observation_space"]["names"] == ["obs_hr", "obs_sbp", "obs_died"]
