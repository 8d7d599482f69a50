"""Clinical CSVs as they come: a treatment column holding text is a discrete action whose labels
are kept in the action space, appended and exported without losing them."""

from __future__ import annotations

import csv
import json

import numpy as np
import pytest

from aoc_cli.errors import AocError
from aoc_cli.formats import ReadOptions, read_dataset
from aoc_cli.store import Store, action_labels

from tests.formats.sources import write_csv


def stays(path, rows):
    """A CSV with columns episode, t, obs_0, treatment, vaso from (episode, t, obs, act, vaso)."""
    return write_csv(path, ["episode", "t", "obs_0", "treatment", "vaso"], rows)


ROWS = [(2, 1, 0.4, "oxygen", 0), (1, 0, 0.1, "none", 1), (1, 1, 0.2, "oxygen", 0),
        (2, 0, 0.3, "none", 2), (3, 0, 0.5, " cpap ", 1)]


def test_a_text_treatment_is_a_labelled_discrete_action(tmp_path):
    data = read_dataset(stays(tmp_path / "log.csv", ROWS),
                        options=ReadOptions(act_columns=["treatment"]))
    assert data.action_space == {"type": "discrete", "n": 3, "names": ["cpap", "none", "oxygen"]}
    # rows ordered by (episode, t): 1/0 none, 1/1 oxygen, 2/0 none, 2/1 oxygen, 3/0 cpap
    assert data.actions.tolist() == [1, 2, 1, 2, 0]
    assert data.actions.dtype == np.int64
    assert action_labels(data.action_space) == ["cpap", "none", "oxygen"]
    assert "vaso" in data.columns  # the other numeric column stays a corpus column


def test_several_action_columns_with_text_label_each_combination(tmp_path):
    data = read_dataset(stays(tmp_path / "log.csv", ROWS),
                        options=ReadOptions(act_columns=["treatment", "vaso"]))
    names = data.action_space["names"]
    assert names == sorted({"treatment=none,vaso=1", "treatment=oxygen,vaso=0",
                            "treatment=none,vaso=2", "treatment=cpap,vaso=1"})
    assert [names[a] for a in data.actions] == [
        "treatment=none,vaso=1", "treatment=oxygen,vaso=0", "treatment=none,vaso=2",
        "treatment=oxygen,vaso=0", "treatment=cpap,vaso=1"]


def test_numeric_actions_are_read_as_before(tmp_path):
    data = read_dataset(stays(tmp_path / "log.csv", ROWS),
                        options=ReadOptions(act_columns=["vaso"], discrete_actions=True))
    assert data.action_space == {"type": "discrete", "n": 3, "names": ["vaso"]}
    assert action_labels(data.action_space) is None  # one name: the column's, not labels


@pytest.mark.parametrize("bad, message", [
    ((1, 1, 0.2, "3", 0), r"column 'treatment' mixes numbers and text \(data row 1 \(episode "
                          r"2\) holds 'oxygen'\)"),
    ((1, 1, 0.2, "", 0), r"column 'treatment', data row 3 \(episode 1\) is empty: every step needs"),
])
def test_mixed_or_missing_treatments_are_one_clear_error(tmp_path, bad, message):
    rows = list(ROWS)
    rows[2] = bad
    with pytest.raises(AocError, match=message):
        read_dataset(stays(tmp_path / "log.csv", rows), options=ReadOptions(act_columns=["treatment"]))


def test_append_merges_labels_keeping_the_existing_codes(tmp_path):
    store = Store(tmp_path / "store")
    first = read_dataset(stays(tmp_path / "a.csv", ROWS[:4]),
                         options=ReadOptions(act_columns=["treatment"]))
    assert first.action_space["names"] == ["none", "oxygen"]
    store.write("c", first)
    more = read_dataset(stays(tmp_path / "b.csv", [(7, 0, 0.0, "cpap", 0), (7, 1, 0.0, "none", 0)]),
                        options=ReadOptions(act_columns=["treatment"]))
    corpus = store.write("c", more, append=True)
    names = corpus.action_space["names"]
    assert names == ["none", "oxygen", "cpap"]
    assert [names[a] for a in corpus.actions] == ["none", "oxygen", "none", "oxygen", "cpap",
                                                  "none"]


def test_labels_survive_export_to_csv_and_ingest_back(tmp_path, store, aoc_inproc):
    path = stays(tmp_path / "log.csv", ROWS)
    code, _, err = aoc_inproc("ingest", str(path), "--name", "c", "--act-columns", "treatment")
    assert code == 0, err
    out = tmp_path / "out" / "c.csv"
    out.parent.mkdir()
    code, _, err = aoc_inproc("export", "c", "--to", "csv", "--out", str(out))
    assert code == 0, err
    with open(out) as fh:
        rows = list(csv.DictReader(fh))
    assert [r["action_label"] for r in rows] == ["none", "oxygen", "none", "oxygen", "cpap"]
    code, _, err = aoc_inproc("ingest", str(out), "--name", "back")
    assert code == 0, err
    manifests = [json.loads((store / n / "manifest.json").read_text()) for n in ("c", "back")]
    assert manifests[1]["action_space"] == manifests[0]["action_space"]
    assert manifests[1]["content_hash"] == manifests[0]["content_hash"]
