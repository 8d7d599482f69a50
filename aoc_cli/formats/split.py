"""One cohort table, two corpora: ``aoc split NAME --test 0.2 --seed 0`` makes ``NAME-train``
and ``NAME-test`` from corpus NAME, by stay or (``--by TAG``) by the values of a tag (a
hospital, a year: every stay of one value falls in one part).

What the ingest fitted on the whole table is fitted again on the training part alone and
applied to both: the imputation medians (the raw values are the stored ones where
``imputed_mask`` is false; the imputed cells are refilled) and the dose-bin edges (the raw
doses are kept as corpus columns; edges given at ingest, ``COL=0:50:180:530``, are kept). The test part's own statistics never enter, so evaluating
on it leaks nothing. The split (the source corpus and its content hash, the share, the seed,
the tag, the parts' names and the test stays) is recorded in both manifests
(``preprocessing["split"]``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from aoc_cli.errors import AocError, param
from aoc_cli.formats import bins as dose_bins
from aoc_cli.formats import impute
from aoc_cli.store import CorpusData, Store, check_name, discrete_space


@dataclass
class SplitResult:
    """What ``aoc split`` prints: one row per part."""

    corpus: str
    parts: list[dict]

    def rows(self) -> list[dict]:
        return self.parts


def choose_test(data: CorpusData, test: float, seed: int, by: str | None) -> np.ndarray:
    """(E,) bool: the stays of the test part, a share ``test`` of the stays (by stay), or of
    the tag ``by``'s values drawn until their stays reach that share."""
    if not 0.0 < test < 1.0:
        raise AocError(f"{param('test', test)} must be a share strictly between 0 and 1")
    rng = np.random.default_rng(seed)
    n = data.n_episodes
    if n < 2:
        raise AocError(f"corpus has {n} episode: nothing to split")
    if by is None:
        k = min(max(int(round(test * n)), 1), n - 1)
        out = np.zeros(n, bool)
        out[rng.permutation(n)[:k]] = True
        return out
    if by not in data.tags:
        known = ", ".join(data.tags) or "none"
        raise AocError(f"{param('by', by)}: the corpus has no tag {by!r} (tags: {known})")
    codes, labels = data.tags[by]
    starts = data.episode_starts
    first = codes[starts[:-1]]
    mixed = np.flatnonzero(np.maximum.reduceat(codes, starts[:-1]) !=
                           np.minimum.reduceat(codes, starts[:-1]))
    if mixed.size:
        raise AocError(f"{param('by', by)}: tag {by!r} changes within episode {int(mixed[0])}: "
                       "split by a tag that is constant within each stay")
    present = np.unique(first)
    if len(present) < 2:
        raise AocError(f"{param('by', by)}: every stay has {by}={labels[present[0]]!r}: "
                       "nothing to split")
    chosen: list[int] = []
    for value in rng.permutation(present):
        if np.isin(first, chosen).mean() >= test or len(chosen) == len(present) - 1:
            break
        chosen.append(int(value))
    return np.isin(first, chosen)


def _raw_observations(data: CorpusData, spec: dict) -> np.ndarray:
    """(N, d) the observations as read, NaN where the ingest imputed them."""
    d = len(spec["names"])
    raw = np.array(data.observations[:, :d], dtype=np.float64)
    if data.imputed is not None:
        raw[data.imputed[:, :d]] = np.nan
    return raw


def refit(train: CorpusData, parts: list[CorpusData], where: str) -> list[CorpusData]:
    """``parts`` with the imputation and dose bins fitted on ``train`` alone (the
    ``COL?measured`` features kept as they were)."""
    pre = dict(train.preprocessing)
    if "impute" in pre:
        old = pre["impute"]
        spec = impute.fit(_raw_observations(train, old), old["names"], old["rule"],
                          old["mask"], where, measured=old["measured"])
        for part in parts:
            raw = _raw_observations(part, old)
            obs = np.empty(part.observations.shape)
            obs[:, :raw.shape[1]] = raw
            part.imputed = impute.fill(obs, part.episode_starts, spec)
            part.observations = obs.astype(part.observations.dtype, copy=False)
            if not part.imputed.any():
                part.imputed = None
        pre["impute"] = spec
    if "bins" in pre:
        old = pre["bins"]
        asked = dose_bins.asked_of(old)  # given edges kept as they are
        spec = dose_bins.fit({c: train.columns[c] for c in old["columns"]}, asked, where)
        labels = dose_bins.labels(spec)
        for part in parts:
            part.actions = dose_bins.cut({c: part.columns[c] for c in old["columns"]}, spec)
            part.action_space = discrete_space(len(labels), labels)
        pre["bins"] = spec
    for part in parts:
        part.preprocessing = dict(pre)
    return parts


def split(name: str, *, store: Store, test: float = 0.2, seed: int = 0, by: str | None = None,
          names: tuple[str, str] | None = None, overwrite: bool = False) -> SplitResult:
    """Split corpus ``name`` into a training and a test corpus (``names``, default
    ``NAME-train`` and ``NAME-test``; module docstring). Nothing is written unless both
    parts are valid."""
    train_name, test_name = names or (f"{name}-train", f"{name}-test")
    for part in (train_name, test_name):
        check_name(part)
        if part == name:
            raise AocError(f"the parts must not replace corpus {name!r}: name them otherwise")
        store.check_writable(part, overwrite=overwrite, append=False, notify=False)
    corpus = store.corpus(name)
    data = corpus.load()
    in_test = choose_test(data, test, seed, by)
    train, held = data.select_episodes(~in_test), data.select_episodes(in_test)
    train, held = refit(train, [train, held], f"corpus {name!r}")
    train.validate(), held.validate()
    ids = data.episode_ids or [str(e) for e in range(data.n_episodes)]
    record = {"corpus": name, "content_hash": corpus.hash, "test": test, "seed": seed,
              "by": by, "train": train_name, "test_corpus": test_name,
              "test_episodes": [ids[e] for e in np.flatnonzero(in_test)]}
    rows = []
    for part, part_name, kind in ((train, train_name, "train"), (held, test_name, "test")):
        part.preprocessing = {**part.preprocessing, "split": {**record, "part": kind}}
        part.source = {**data.source, "split_from": name}
        written = store.write(part_name, part, overwrite=overwrite)
        rows.append({"name": part_name, "part": kind, "rows": written.n_rows,
                     "episodes": written.n_episodes,
                     "share": round(written.n_episodes / data.n_episodes, 4)})
    return SplitResult(name, rows)
