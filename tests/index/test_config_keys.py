"""A setting's name misspelt is an error that names it, not a setting silently dropped; a saved
artefact's config written by an older aoc still reads."""

import numpy as np
import pytest

from aoc_cli.belief.config import BeliefConfig
from aoc_cli.errors import AocError
from aoc_cli.index.search import BeliefIndex
from aoc_cli.index.search.config import IndexConfig


def test_an_unknown_index_setting_is_refused_with_its_name():
    with pytest.raises(AocError, match=r"unknown index setting kidn:.*\bkind\b"):
        IndexConfig.from_dict({"kidn": "hnsw"})
    beliefs = np.random.default_rng(0).normal(size=(50, 4)).astype(np.float32)
    with pytest.raises(AocError, match=r"\bkidn\b"):
        BeliefIndex.build(beliefs, kidn="hnsw")
    assert BeliefIndex.build(beliefs, kind="flat").kind == "flat"


def test_a_saved_config_with_a_key_of_an_older_aoc_still_reads():
    assert IndexConfig.from_dict({"kind": "flat", "retired": 1}, strict=False).kind == "flat"
    config = BeliefConfig.from_dict({"hidden": 32, "retired": 1}, strict=False)
    assert config.hidden == 32


def test_an_unknown_belief_setting_is_refused_with_its_name():
    with pytest.raises(AocError, match="unknown belief setting hiden:"):
        BeliefConfig.from_dict({"hiden": 32})
