"""Lazy re-exports of a package's public names (PEP 562), one implementation for every package
that must not load its heavy modules on import (``aoc_cli.api``, ``belief``, ``index``,
``index.search``, ``control``, ``training``, ``explanation``: ``import aoc_cli`` and
``aoc --help`` load no torch, FAISS or environments).

>>> __getattr__, __dir__ = exports(__name__, {"train_model": "train"})   # doctest: +SKIP

``where`` maps each public name to the submodule that defines it. A name is imported on its
first use and bound in the package, so later uses are plain attribute reads. No submodule may
be named after a public name: importing a submodule binds its name in the package, which
would hide the name (:func:`exports` refuses such a map when it is built).
"""

from __future__ import annotations

import importlib
import importlib.util
import sys
from collections.abc import Callable


def exports(package: str, where: dict[str, str]) -> tuple[Callable, Callable]:
    """(``__getattr__``, ``__dir__``) for ``package`` (its ``__name__``), whose public names are
    the keys of ``where`` (name -> submodule, relative to the package)."""
    clash = sorted(n for n in where if importlib.util.find_spec(f"{package}.{n}") is not None)
    if clash:
        raise ImportError(f"{package}: submodules named after public names: {clash}")

    def __getattr__(name: str):
        if name not in where:
            raise AttributeError(f"module {package!r} has no attribute {name!r}")
        value = getattr(importlib.import_module(f"{package}.{where[name]}"), name)
        setattr(sys.modules[package], name, value)
        return value

    def __dir__() -> list[str]:
        return sorted(set(vars(sys.modules[package])) | set(where))

    return __getattr__, __dir__
