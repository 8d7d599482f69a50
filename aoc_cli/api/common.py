"""What every entry of the API shares: the store argument, the log argument."""

from __future__ import annotations

import os
from typing import Callable

from aoc_cli.belief.config import BeliefConfig
from aoc_cli.control.config import ControllerConfig, ControllerLike, given_settings
from aoc_cli.store import Store

__all__ = ["BeliefConfig", "ControllerConfig", "Log", "Store", "StoreLike", "controller_config",
           "open_store"]

#: ``store=``: a Store, a folder, or None ($AOC_STORE, else ./corpora).
StoreLike = Store | str | os.PathLike | None
#: ``log=``: a function of one line of text (the notes a command prints on stderr).
Log = Callable[[str], None]


def open_store(store: StoreLike) -> Store:
    """The store ``store`` names."""
    return store if isinstance(store, Store) else Store.open(store)


def controller_config(controller: ControllerLike) -> ControllerConfig | dict:
    """What a deciding entry hands to :func:`aoc_cli.control.open_session`: a
    ControllerConfig whole, as given; else the settings ``controller`` gives (a mapping of
    its fields; None: none), checked now (a bad one fails before any store is read), which
    the session lays over the settings saved with the model
    (:meth:`ControllerConfig.for_model`)."""
    if isinstance(controller, ControllerConfig):
        return controller
    given = given_settings(controller)
    ControllerConfig(**given)
    return given
