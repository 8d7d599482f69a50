"""aoc_cli.lazy: one implementation of the packages' lazy public names."""
from __future__ import annotations

import sys
import types

import pytest

from aoc_cli import lazy


def test_a_name_is_imported_on_first_use_and_bound_in_the_package():
    import aoc_cli.index.search as index
    getattr_, dir_ = lazy.exports("aoc_cli.index.search", {"IndexConfig": "config"})
    from aoc_cli.index.search.config import IndexConfig
    assert getattr_("IndexConfig") is IndexConfig
    assert vars(index)["IndexConfig"] is IndexConfig and "IndexConfig" in dir_()
    with pytest.raises(AttributeError, match="no attribute 'nothing'"):
        getattr_("nothing")


def test_a_submodule_named_after_a_public_name_is_refused():
    # aoc_cli.api.data is a submodule: a public name "data" would be hidden once it is imported
    with pytest.raises(ImportError, match=r"\['data'\]"):
        lazy.exports("aoc_cli.api", {"data": "data", "train": "model"})


def test_every_lazy_package_gives_its_names_not_modules():
    for name in ("aoc_cli.api", "aoc_cli.belief", "aoc_cli.index", "aoc_cli.index.search",
                 "aoc_cli.control", "aoc_cli.training", "aoc_cli.explanation"):
        package = sys.modules.get(name) or __import__(name, fromlist=["_"])
        for public in package.__all__:
            assert not isinstance(getattr(package, public), types.ModuleType), (name, public)
