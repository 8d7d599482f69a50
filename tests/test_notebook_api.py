"""The notebook API: the library's types exported lazily from aoc_cli, short reprs, the
belief's settings as one argument to train (the flat keyword arguments deprecated)."""

from __future__ import annotations

import subprocess
import sys
import warnings

import numpy as np
import pytest

import aoc_cli
from aoc_cli.api.model import belief_given
from aoc_cli.errors import BadSetting


def test_the_types_are_exported_lazily_and_import_no_torch():
    probe = ("import sys\nimport aoc_cli\n"
             "aoc_cli.Store, aoc_cli.ControllerConfig, aoc_cli.BeliefConfig\n"
             "print(sorted(m for m in ('torch', 'faiss') if m in sys.modules))\n"
             "print(aoc_cli.Session.__module__, aoc_cli.Evaluation.__module__, "
             "aoc_cli.Explained.__module__, aoc_cli.Decision.__module__)")
    out = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True,
                         check=True).stdout.split("\n")
    assert out[0] == "[]"
    assert out[1] == ("aoc_cli.api.session aoc_cli.api.evaluation aoc_cli.api.explanation "
                      "aoc_cli.control.controller")
    assert set(aoc_cli.TYPES) <= set(dir(aoc_cli)) and set(aoc_cli.TYPES) <= set(aoc_cli.__all__)


def test_a_decision_prints_in_one_line_without_its_candidates():
    d = aoc_cli.Decision(action=np.array([0.5, -0.25]), value=1.5, residual=0.01,
                         support_rows=np.arange(8), support_weights=np.full(8, 1 / 8),
                         support_distances=np.zeros(8), candidates=np.random.rand(100, 2),
                         candidate_residuals=np.zeros(100), candidate_values=np.zeros(100),
                         passed=np.ones(100, bool), chosen=0, threshold=0.1,
                         warnings=["<b>x</b>"])
    text = repr(d)
    assert text.startswith("Decision(action=[0.5, -0.25], value=1.5, residual=0.01, support=[0:")
    assert "candidates=100" in text and ", ..." in text and len(text) < 200
    assert "&lt;b&gt;" in d._repr_html_()
    frame = d.to_frame()
    assert list(frame.columns) == ["row", "weight", "distance", "episodes_here"]
    assert len(frame) == 8


def test_the_belief_settings_as_one_argument():
    assert belief_given("critic") == {"belief": "critic"}
    assert belief_given({"mode": "imitation", "hidden": None}) == {"mode": "imitation"}
    whole = belief_given(aoc_cli.BeliefConfig(max_epochs=3))
    assert whole["max_epochs"] == 3 and whole["mode"] == "value"
    with pytest.raises(BadSetting, match="unknown belief setting"):
        belief_given({"epochs": 3})
    with pytest.raises(BadSetting, match="given twice"):
        belief_given({"max_epochs": 3}, {"max_epochs": 4})
    with pytest.raises(BadSetting, match="must be a BeliefConfig"):
        belief_given(3)


def test_the_flat_arguments_still_work_with_a_deprecation_warning(tmp_path):
    with pytest.warns(DeprecationWarning, match=r"belief=\{'label_smoothing': \.\.\.\}"):
        with pytest.raises(BadSetting):      # checked before the store is read
            aoc_cli.train("none", store=tmp_path, label_smoothing=2.0)
    with warnings.catch_warnings():
        warnings.simplefilter("error", DeprecationWarning)
        with pytest.raises(BadSetting):
            aoc_cli.train("none", store=tmp_path, belief={"label_smoothing": 2.0})
