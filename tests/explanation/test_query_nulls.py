"""An explain query holding null on a corpus ingested with --impute: filled with the corpus's
own medians (or, with hold, the query's previous step), never refused, never its own."""

import json

import numpy as np
import pytest

import aoc_cli
from aoc_cli.explanation.decisions import parse_query
from aoc_cli.errors import AocError
from aoc_cli.store import Store
from tests.formats.cohorts import OBS, cohort, roles, write


@pytest.mark.parametrize("rule", ["median", "hold"])
def test_null_cells_of_a_query_take_the_corpus_medians_and_measured_features(tmp_path, rule):
    store = Store(tmp_path / "s")
    path = write(cohort(stays=20, gap=0.4), tmp_path / "c.csv")
    aoc_cli.ingest(path, "icu", store=store, options=roles(
        act_columns=["input_4hourly"], impute=rule, impute_mask=True))
    c = store.corpus("icu")
    spec = c.preprocessing["impute"]
    base = np.array(c.observations[0, :len(OBS)], dtype=float)
    query = base.tolist()
    query[2] = None  # HR unmeasured
    obs, hist, _a, _c = parse_query(json.dumps({"observation": query}), 1, c, 2)
    assert obs.shape == (c.observation_dim,)
    assert obs[2] == np.float32(spec["medians"][2])
    names = c.observation_space["names"]
    assert obs[names.index("HR?measured")] == 0.0
    # the full width with the measured features: only the null is filled
    full = np.array(c.observations[0], dtype=float).tolist()
    full[3] = None
    obs, *_ = parse_query(json.dumps({"observation": full}), 1, c, 2)
    assert obs[3] == np.float32(spec["medians"][3])
    # a history step before the query: hold carries its value forward, median does not
    step = np.array(c.observations[0], dtype=float)
    step[2] = 123.0
    line = json.dumps({"observation": query, "history": [step.tolist() + [0.0, 0.0]]})
    obs, hist, *_ = parse_query(line, 1, c, 2)
    assert obs[2] == np.float32(123.0 if rule == "hold" else spec["medians"][2])
    assert hist.mask.sum() == 1


def test_a_null_on_a_corpus_without_imputation_is_refused(tmp_path):
    store = Store(tmp_path / "s")
    path = write(cohort(stays=5, gap=0.0), tmp_path / "c.csv")
    aoc_cli.ingest(path, "plain", store=store, options=roles(act_columns=["input_4hourly"]))
    c = store.corpus("plain")
    query = [None] + [0.0] * (c.observation_dim - 1)
    with pytest.raises(AocError, match="holds null, NaN or inf.*impute"):
        parse_query(json.dumps({"observation": query}), 1, c, 2)
