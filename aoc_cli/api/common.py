"""What every entry of the API shares: the store argument, the log argument."""

from __future__ import annotations

import os
from typing import Callable

from aoc_cli.store import Store

#: ``store=``: a Store, a folder, or None ($AOC_STORE, else ./corpora).
StoreLike = Store | str | os.PathLike | None
#: ``log=``: a function of one line of text (the notes a command prints on stderr).
Log = Callable[[str], None]


def open_store(store: StoreLike) -> Store:
    """The store ``store`` names."""
    return store if isinstance(store, Store) else Store.open(store)
