import json

import numpy as np
import pytest

from aoc_cli.errors import AocError
from aoc_cli.formats import ReadOptions, detect_format, ingest, read_dataset
from aoc_cli.store import Store
from tests.formats.sources import write_csv


def patients(seed=0, ids=("p10", "p2", "p7"), lengths=(4, 3, 5)):
    """Rows (id, t, obs_hr, obs_bp, act_dose, reward, ward) in episode order."""
    rng = np.random.default_rng(seed)
    rows = []
    for pid, t in zip(ids, lengths):
        for step in range(t):
            rows.append([pid, step * 2.5, round(rng.normal(80, 5), 3), round(rng.normal(120, 9), 3),
                         int(rng.integers(0, 2)), round(rng.normal(), 4), "icu" if pid != "p2"
                         else "ward"])
    return rows


HEADER = ["id", "t", "obs_hr", "obs_bp", "act_dose", "reward", "ward"]


def test_csv_rows_are_ordered_by_id_and_time_whatever_the_file_order(tmp_path):
    rows = patients()
    shuffled = [rows[i] for i in np.random.default_rng(1).permutation(len(rows))]
    path = write_csv(tmp_path / "log.csv", HEADER, shuffled)
    assert detect_format(path) == "csv"
    ingest(path, "icu", store=Store(tmp_path / "s"),
           options=ReadOptions(discrete_actions=True, tag_columns=["ward"]))
    c = Store(tmp_path / "s").corpus("icu")
    ordered = sorted(rows, key=lambda r: (r[0], r[1]))  # ids are text: p10 < p2 < p7
    assert (c.n_rows, c.n_episodes) == (12, 3)
    np.testing.assert_array_equal(c.episode_starts, [0, 4, 7, 12])
    np.testing.assert_allclose(c.observations, [[r[2], r[3]] for r in ordered], rtol=1e-6)
    np.testing.assert_array_equal(c.actions, [r[4] for r in ordered])
    assert c.discrete and c.n_actions == 2
    np.testing.assert_allclose(c.rewards, [r[5] for r in ordered])
    np.testing.assert_allclose(
        c.episode_returns(), [sum(r[5] for r in ordered if r[0] == p) for p in ("p10", "p2", "p7")])
    assert c.load().episode_ids == ["p10", "p2", "p7"]
    assert c.observation_space["names"] == ["obs_hr", "obs_bp"]
    codes, labels = c.tag("ward")
    assert labels == ["icu", "ward"] and codes.tolist() == [0] * 4 + [1] * 3 + [0] * 5
    # the time column is a numeric corpus column? no: it is a role, not a leftover
    assert c.manifest["columns"] == []
    assert np.flatnonzero(c.read("terminals")).tolist() == [3, 6, 11]


def test_numeric_ids_sort_numerically_and_iso_times_sort_as_dates(tmp_path):
    rows = [[10, "2024-01-02T00:00", 1.0, 0.5], [2, "2024-01-01T12:00", 2.0, 0.1],
            [10, "2024-01-01T00:00", 3.0, 0.2], [2, "2024-01-01T06:00", 4.0, 0.3]]
    path = write_csv(tmp_path / "x.csv", ["episode", "time", "obs_a", "act_u"], rows)
    data = read_dataset(path)
    assert data.episode_ids == ["2", "10"]
    np.testing.assert_array_equal(data.observations[:, 0], [4.0, 2.0, 3.0, 1.0])
    assert data.rewards is None


def test_static_features_are_joined_onto_every_step_and_named(tmp_path):
    rows = patients()
    path = write_csv(tmp_path / "log.csv", HEADER, rows)
    static = write_csv(tmp_path / "static.csv", ["id", "age", "sex"],
                       [["p7", 71, "F"], ["p10", 45, "M"], ["p2", 60, "F"]])
    data = read_dataset(path, options=ReadOptions(static=static, discrete_actions=True))
    assert data.observation_space["names"] == ["obs_hr", "obs_bp", "age", "sex=F", "sex=M"]
    assert data.observation_space["static"] == ["age", "sex=F", "sex=M"]
    # episode order p10 (4 rows), p2 (3), p7 (5)
    np.testing.assert_array_equal(data.observations[:, 2], [45] * 4 + [60] * 3 + [71] * 5)
    np.testing.assert_array_equal(data.observations[:, 3], [0] * 4 + [1] * 3 + [1] * 5)
    np.testing.assert_array_equal(data.observations[:, 4], [1] * 4 + [0] * 3 + [0] * 5)


def test_static_file_missing_an_id_is_refused(tmp_path):
    path = write_csv(tmp_path / "log.csv", HEADER, patients())
    static = write_csv(tmp_path / "static.csv", ["id", "age"], [["p7", 71], ["p10", 45]])
    with pytest.raises(AocError, match="no row for episode id 'p2'"):
        read_dataset(path, options=ReadOptions(static=static))


def test_column_mapping_file_names_the_roles(tmp_path):
    rows = [["a", 1, 0.1, 0.2, 1.5, 0], ["a", 0, 0.3, 0.4, 2.5, 1], ["b", 0, 0.5, 0.6, 3.5, 0]]
    path = write_csv(tmp_path / "x.csv", ["patient", "hour", "hr", "bp", "score", "treat"], rows)
    mapping = tmp_path / "roles.json"
    mapping.write_text(json.dumps({"id": "patient", "time": "hour", "observations": ["hr", "bp"],
                                   "actions": ["treat"], "reward": "score",
                                   "discrete_actions": True}))
    data = read_dataset(path, options=ReadOptions(columns_file=mapping))
    np.testing.assert_allclose(data.observations, [[0.3, 0.4], [0.1, 0.2], [0.5, 0.6]])
    np.testing.assert_array_equal(data.actions, [1, 0, 0])
    np.testing.assert_allclose(data.rewards, [2.5, 1.5, 3.5])
    assert data.source["roles"]["id"] == "patient"


def test_flags_override_defaults_and_leftover_numeric_columns_are_kept(tmp_path):
    rows = [[0, 0, 1.0, 0.5, 7.0], [0, 1, 2.0, 0.6, 8.0]]
    path = write_csv(tmp_path / "x.csv", ["episode", "t", "x", "u", "sofa"], rows)
    data = read_dataset(path, options=ReadOptions(obs_columns=["x"], act_columns=["u"]))
    np.testing.assert_array_equal(data.columns["sofa"], [7.0, 8.0])
    assert data.action_space["names"] == ["u"]


def test_non_numeric_observation_cell_is_named(tmp_path):
    path = write_csv(tmp_path / "x.csv", ["episode", "t", "obs_a", "act_u"],
                     [[0, 0, 1.0, 0.1], [0, 1, "high", 0.2]])
    with pytest.raises(AocError, match=r"column 'obs_a', data row 2 \(episode 0\) holds 'high'"):
        read_dataset(path)


def test_quoted_fields_may_span_lines_and_blank_lines_are_skipped(tmp_path):
    """A spreadsheet export with a free-text note column: a note holding a line break and a
    comma stays one field of one row; a blank line is no row."""
    text = ('id,t,obs_a,act_u,note\n'
            'p1,0,1.5,0,"calm"\n'
            'p1,1,2.5,1,"short of breath,\nO2 started"\n'
            '\n'
            'p2,0,3.5,0,""\n')
    path = tmp_path / "notes.csv"
    path.write_text(text)
    data = read_dataset(path, options=ReadOptions(tag_columns=["note"]))
    assert data.episode_ids == ["p1", "p2"]
    np.testing.assert_array_equal(data.observations[:, 0], [1.5, 2.5, 3.5])
    np.testing.assert_array_equal(data.actions[:, 0], [0, 1, 0])
    codes, labels = data.tags["note"]
    assert labels[codes[1]] == "short of breath,\nO2 started"


def test_a_row_with_too_many_fields_names_its_line(tmp_path):
    path = tmp_path / "bad.csv"
    path.write_text('id,t,obs_a,act_u\np1,0,"two\nlines",0\np1,1,2.0,0,9\n')
    with pytest.raises(AocError, match=r"data row 2 \(line 4\) has 5 fields, the header has 4"):
        read_dataset(path)


def test_reading_reports_progress_in_bytes_up_to_the_whole_file(tmp_path):
    from aoc_cli.formats.table import read_table

    path = tmp_path / "p.csv"
    path.write_text("a,b\n" + "".join(f"{i},{i}\n" for i in range(7)))
    seen = []
    table = read_table(path, lambda *a: seen.append(a))
    assert table.header == ["a", "b"] and list(table.cols["a"]) == list(range(7))
    size = path.stat().st_size
    assert seen == [(0, size, "reading p.csv"), (size, size, "reading p.csv")]


def test_a_file_with_more_rows_than_its_first_mb_suggests_reads_every_row(tmp_path):
    """The streamed reader sizes its arrays from the first MB's lines (long notes there, short
    rows after): the arrays grow, and every row's numbers come back in order."""
    from aoc_cli.formats.table import read_table

    path = tmp_path / "grow.csv"
    n_long, n = 2_000, 60_000
    with path.open("w") as fh:
        fh.write("id,t,obs_a,act_u,note\n")
        for i in range(n):
            note = "x" * 600 if i < n_long else ""
            fh.write(f"p{i // 10},{i % 10},{i * 0.5},{i % 3},{note}\n")
    table = read_table(path, text_columns=["id"])
    assert table.n == n
    np.testing.assert_array_equal(table.cols["obs_a"], np.arange(n) * 0.5)
    np.testing.assert_array_equal(table.cols["act_u"], np.arange(n) % 3)


@pytest.mark.parametrize("trailing_newline", [True, False])
def test_a_csv_read_as_two_halves_is_the_csv_read_as_one_stream(tmp_path, monkeypatch,
                                                               trailing_newline):
    """A large plain CSV without quotes is read in two threads, its second half with the
    first's names and types: the same columns as one stream (blank lines, text and number
    columns, the last line with or without its line break); a file holding a quote is one
    stream."""
    from aoc_cli.formats import csv_stream as cs
    from aoc_cli.formats import table as t

    path = tmp_path / "halves.csv"
    lines = ["id,t,obs_a,act_u,note"]
    for i in range(5_000):
        lines.append(f"p{i // 7},{i % 7},{'' if i % 11 == 0 else i * 0.25},{i % 3},n{i % 5}")
        if i % 997 == 0:
            lines.append("")  # blank lines are skipped
    path.write_text("\n".join(lines) + ("\n" if trailing_newline else ""))
    monkeypatch.setattr(cs, "BLOCK_BYTES", 4096)
    monkeypatch.setattr(cs, "SPLIT_BYTES", 1 << 40)
    one = t.read_table(path, text_columns=["id"])
    monkeypatch.setattr(cs, "SPLIT_BYTES", 1024)
    halves = cs.halves(path)
    assert halves is not None and 0 < halves.middle < path.stat().st_size
    two = t.read_table(path, text_columns=["id"])
    assert two.n == one.n == 5_000 and two.header == one.header
    for name in one.header:
        a, b = one.cols[name], two.cols[name]
        if isinstance(a, np.ndarray):  # streamed (not the whole-file fallback) both times
            assert isinstance(b, np.ndarray)
            np.testing.assert_array_equal(b, a)
        else:
            assert b.to_pylist() == a.to_pylist()
    path.write_text(path.read_text().replace("n3", '"n3"'))
    assert cs.halves(path) is None
