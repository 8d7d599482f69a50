"""What aoc train decided, one record (aoc_cli.training.record): the saved metrics' entries in
the order training has always written them, each step laid over a new record."""

from __future__ import annotations

import dataclasses

import pytest

from aoc_cli.training.record import Recording, TrainingRecord


def test_the_entries_keep_the_order_of_the_saved_metrics():
    paper = TrainingRecord({"k": 42}, selection={"searched": []})
    assert list(paper.as_dict()) == ["controller", "selection"]
    read = TrainingRecord({"k": 42}, settings={"evidence": {}, "decided": [], "seconds": 0.1},
                          label_smoothing_rule="rare")
    assert list(read.as_dict()) == ["settings", "controller", "label_smoothing_rule"]


def test_each_step_gives_a_new_record_and_leaves_the_old_one_alone():
    first = TrainingRecord({"residual_cap": 0.01},
                           settings={"evidence": {}, "decided": [{"setting": "mode"}],
                                     "seconds": 0.1})
    later = first.with_controller(k=42, support_penalty=2.0).deciding({"setting": "x"}) \
        .with_settings(support_penalty={"noise": 1.0})
    assert first.controller == {"residual_cap": 0.01}
    assert first.settings["decided"] == [{"setting": "mode"}]
    assert list(later.controller) == ["residual_cap", "k", "support_penalty"]
    assert list(later.settings) == ["evidence", "decided", "seconds", "support_penalty"]
    assert [r["setting"] for r in later.settings["decided"]] == ["mode", "x"]
    with pytest.raises(dataclasses.FrozenInstanceError):
        later.controller = {}  # type: ignore[misc]


def test_a_recording_gives_the_entries_of_its_last_record():
    recording = Recording(TrainingRecord({"k": 42}))
    recording.record = recording.record.with_controller(epsilon=0.1)
    assert recording() == {"controller": {"k": 42, "epsilon": 0.1}}
