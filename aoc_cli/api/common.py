"""What every entry of the API shares: the store argument, the log argument."""

from __future__ import annotations

import os
from typing import Callable

from aoc_cli.control.config import ControllerConfig, ControllerLike, given_settings
from aoc_cli.store import Store

#: ``store=``: a Store, a folder, or None ($AOC_STORE, else ./corpora).
StoreLike = Store | str | os.PathLike | None
#: ``log=``: a function of one line of text (the notes a command prints on stderr).
Log = Callable[[str], None]


def open_store(store: StoreLike) -> Store:
    """The store ``store`` names."""
    return store if isinstance(store, Store) else Store.open(store)


def controller_config(controller: ControllerLike, task: str | None) -> ControllerConfig:
    """The controller's settings of a deciding entry: those ``controller`` gives (a
    ControllerConfig or a mapping of its fields; None: not given) over the task's own over
    the paper's defaults (:meth:`ControllerConfig.for_task`)."""
    return ControllerConfig.for_task(task, **given_settings(controller))
