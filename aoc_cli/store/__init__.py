"""Corpus store: schema, atomic writes, manifest, histories.

>>> from aoc_cli.store import Store
>>> corpus = Store.open().corpus("pendulum")      # doctest: +SKIP
>>> h = corpus.history([10, 11], length=4)         # doctest: +SKIP
"""

from aoc_cli.store.atomic import (
    atomic_dir,
    atomic_path,
    file_record,
    hash_arrays,
    hash_file,
    seal,
    seal_status,
    write_json,
    write_npy,
)
from aoc_cli.store.corpus import (
    CorpusData,
    action_labels,
    History,
    box_space,
    discrete_space,
    episode_starts_from_lengths,
    gather_history,
)
from aoc_cli.store.layout import (DEFAULT_INDEX, DEFAULT_MODEL, index_dir, model_dir,
                                  store_root, targets_dir)
from aoc_cli.store.lock import writing_corpus, writing_model
from aoc_cli.store.reader import Corpus
from aoc_cli.store.store import Store, check_name
from aoc_cli.store.writer import concat
from aoc_cli.store.summary import built_from, list_corpora, summarize


def open_corpus(name: str, store=None) -> Corpus:
    """Open corpus ``name`` of the store at ``store`` (:func:`aoc_cli.store.layout.store_root`)."""
    return Store.open(store).corpus(name)


__all__ = [
    "Corpus",
    "DEFAULT_INDEX",
    "DEFAULT_MODEL",
    "action_labels",
    "CorpusData",
    "History",
    "Store",
    "atomic_dir",
    "atomic_path",
    "box_space",
    "built_from",
    "check_name",
    "concat",
    "discrete_space",
    "episode_starts_from_lengths",
    "file_record",
    "gather_history",
    "hash_arrays",
    "hash_file",
    "index_dir",
    "list_corpora",
    "model_dir",
    "open_corpus",
    "seal",
    "seal_status",
    "store_root",
    "summarize",
    "targets_dir",
    "write_json",
    "write_npy",
    "writing_corpus",
    "writing_model",
]
