"""bench ward: the features the scikit-learn baselines read, and the summary over splits."""

import numpy as np

from aoc_cli.experiments.ward import history_features, summarise


def test_history_features_are_the_previous_steps_of_the_same_stay():
    obs = np.arange(10, dtype=float).reshape(5, 2)          # rows 0-1 one stay, 2-4 another
    act = np.array([1, 0, 1, 1, 0])
    x = history_features(obs, act, np.array([0, 2, 5]), 1)
    assert x.shape == (5, 2 + 4)
    np.testing.assert_array_equal(x[:, :2], obs)
    np.testing.assert_array_equal(x[:, 5], [0, 1, 0, 1, 1])        # a previous step present
    np.testing.assert_array_equal(x[1, 2:5], [0, 1, 1])            # row 0's obs and action
    np.testing.assert_array_equal(x[2, 2:5], [0, 0, 0])            # a new stay: padding
    np.testing.assert_array_equal(x[4, 2:5], [6, 7, 1])
    assert history_features(obs, act, np.array([0, 2, 5]), 0).shape == (5, 2)


def test_summary_is_mean_and_std_over_splits():
    rows = [{"method": "abc", "accuracy": a, "auc": u} for a, u in ((0.9, 0.8), (0.95, 0.9))]
    (s,) = summarise(rows)
    assert s["splits"] == 2 and abs(s["accuracy_mean"] - 0.925) < 1e-12
    assert abs(s["auc_std"] - 0.05) < 1e-12


def test_rows_csv_takes_every_key_in_first_seen_order(tmp_path):
    from aoc_cli.experiments.results import write_rows_csv

    rows = [{"method": "abc", "auc": 0.5}, {"method": "knn", "split": 1, "auc": 0.25}]
    write_rows_csv(tmp_path / "r.csv", rows)
    assert (tmp_path / "r.csv").read_text() == "method,auc,split\nabc,0.5,\nknn,0.25,1\n"
    assert not list(tmp_path.glob("*.tmp"))


def test_a_run_stopped_part_way_keeps_the_splits_it_finished(tmp_path, monkeypatch):
    import csv

    import pytest

    from aoc_cli.experiments import ward

    monkeypatch.setattr(ward, "source_log", lambda source, patients, seed=0: object())

    def split(store, data, s, patients, seed=0, name="ward"):
        if s == 2:
            raise KeyboardInterrupt           # the user stops the run during split 2
        return [{"method": "abc", "accuracy": 0.9 + s / 100, "auc": 0.95, "split": s}]

    monkeypatch.setattr(ward, "run_split", split)
    with pytest.raises(KeyboardInterrupt):
        ward.run_ward(tmp_path / "out", tmp_path / "store", scale="quick")
    with open(tmp_path / "out" / "results.csv") as f:
        kept = list(csv.DictReader(f))
    assert [(r["split"], r["accuracy"]) for r in kept] == [("0", "0.9"), ("1", "0.91")]
    assert not (tmp_path / "out" / "summary.json").exists()
