"""A corpus as a Minari dataset, written by minari's own writer.

``minari.create_dataset_from_buffers`` writes the dataset (one ``EpisodeBuffer`` per episode,
later batches through the same storage's ``update_episodes``) with the observation space a
``Box`` of the corpus's dtype and bounds and the action space a ``Box`` or ``Discrete``; no
environment is recorded, so ``minari.load_dataset`` reads it without one. ``metadata.json``
holds the export spec under ``aoc`` (:mod:`aoc_cli.formats.spec`: spaces with names and
labels, tag labels, episode ids); each episode's ``infos/<tag>`` holds the tag codes and
``infos/<column>`` the numeric columns (T + 1 entries, as Minari's infos have; the last
repeats the one before).

A Minari episode holds T + 1 observations for T actions; a corpus does not record the
observation after the last action, so the last one repeats the one before (the dataset's
``description`` says so). A reward-free corpus is written with zero rewards (Minari requires
rewards); the spec says there were none.

minari writes into its datasets root, ``$MINARI_DATASETS_PATH``: it is pointed, for the
call only, at a scratch folder inside the temporary beside ``--out``, and the dataset folder
is then renamed into place; the user's own datasets root is never touched.
"""

from __future__ import annotations

import contextlib
import os
import re
import shutil
import warnings
from pathlib import Path

import numpy as np

from aoc_cli.errors import AocError
from aoc_cli.formats.minari import datasets_root
from aoc_cli.progress import Progress
from aoc_cli.store import CorpusData, atomic_dir

BATCH_EPISODES = 512
_ID = re.compile(r"^[A-Za-z0-9_.-]+-v\d+$")
DESCRIPTION = ("Exported by aoc from corpus {name!r}. Each episode's last observation repeats "
               "the one before: the corpus does not record the observation after the last "
               "action.")


@contextlib.contextmanager
def datasets_path(folder: Path):
    """``$MINARI_DATASETS_PATH`` set to ``folder`` inside the block, restored after."""
    old = os.environ.get("MINARI_DATASETS_PATH")
    os.environ["MINARI_DATASETS_PATH"] = str(folder)
    try:
        yield
    finally:
        if old is None:
            os.environ.pop("MINARI_DATASETS_PATH", None)
        else:
            os.environ["MINARI_DATASETS_PATH"] = old


def dataset_id(out: Path, corpus: str) -> str:
    """The Minari id of a dataset written to ``out``: its path below the local datasets root
    when it is under it (loadable by that id), else its folder name when it reads
    ``name-vN``, else ``<corpus>-v0``."""
    root = Path(os.path.abspath(datasets_root()))
    target = Path(os.path.abspath(out))
    if root in target.parents:
        rel = target.relative_to(root).as_posix()
        if all(_ID.match(p) or re.match(r"^[A-Za-z0-9_.-]+$", p) for p in rel.split("/")) \
                and _ID.match(target.name):
            return rel
    if _ID.match(target.name):
        return target.name
    name = re.sub(r"[^A-Za-z0-9_.-]", "-", corpus) or "corpus"
    return f"{name}-v0"


def spaces(spec: dict, observations: np.ndarray, actions: np.ndarray):
    """(observation space, action space) as gymnasium spaces."""
    from gymnasium import spaces as gs  # here: gymnasium takes ~0.2 s to import, Minari only

    def bounds(space, dim):
        low = np.array([-np.inf if x is None else x for x in space.get("low") or
                        [None] * dim], np.float64)
        high = np.array([np.inf if x is None else x for x in space.get("high") or
                         [None] * dim], np.float64)
        return low, high

    obs = spec["observation_space"]
    d_o = observations.shape[1]
    low, high = bounds(obs, d_o)
    obs_space = gs.Box(low.astype(observations.dtype), high.astype(observations.dtype),
                       (d_o,), observations.dtype)
    act = spec["action_space"]
    if act.get("type") == "discrete":
        act_space = gs.Discrete(int(act["n"]))
    else:
        d_a = actions.shape[1]
        low, high = bounds(act, d_a)
        act_space = gs.Box(low.astype(actions.dtype), high.astype(actions.dtype), (d_a,),
                           actions.dtype)
    return obs_space, act_space


def _buffers(data: CorpusData, episodes, buffer_type):
    """One ``EpisodeBuffer`` per episode of ``episodes``."""
    starts = np.asarray(data.episode_starts)
    obs = np.asarray(data.observations)
    act = np.asarray(data.actions)
    rew = np.zeros(data.n_rows) if data.rewards is None else np.asarray(data.rewards)
    term = np.asarray(data.terminals, bool)
    trunc = np.asarray(data.truncations, bool)
    out = []
    for e in episodes:
        a, b = int(starts[e]), int(starts[e + 1])
        rows = np.append(np.arange(a, b), b - 1)  # T + 1: the last observation repeated
        infos = {k: np.asarray(c, np.int32)[rows] for k, (c, _lab) in data.tags.items()}
        infos.update({k: np.asarray(v, np.float64)[rows] for k, v in data.columns.items()})
        out.append(buffer_type(id=int(e), observations=obs[rows], actions=act[a:b],
                               rewards=rew[a:b].astype(np.float64), terminations=term[a:b],
                               truncations=trunc[a:b], infos=infos))
    return out


def write_minari(data: CorpusData, spec: dict, out: Path,
                 progress: Progress | None = None) -> list[Path]:
    """Write ``data`` (with its export ``spec``) as the Minari dataset folder ``out``."""
    # here, not at the top: minari's writer imports in ~0.4 s, and only this format needs it
    import minari
    from minari.data_collector import EpisodeBuffer

    clash = sorted(set(data.tags) & set(data.columns))
    if clash:
        raise AocError(f"{clash[0]!r} is both a tag and a column of the corpus: both would be "
                       f"infos/{clash[0]}; export to CSV instead")
    obs_space, act_space = spaces(spec, np.asarray(data.observations),
                                  np.asarray(data.actions))
    ident = dataset_id(out, spec["corpus"])
    batches = [range(i, min(i + BATCH_EPISODES, data.n_episodes))
               for i in range(0, data.n_episodes, BATCH_EPISODES)]
    with atomic_dir(out) as tmp:
        tmp = Path(os.path.abspath(tmp))
        scratch = tmp / "scratch"
        scratch.mkdir()
        with datasets_path(scratch), warnings.catch_warnings():
            warnings.simplefilter("ignore")
            dataset = minari.create_dataset_from_buffers(
                ident, _buffers(data, batches[0], EpisodeBuffer),
                observation_space=obs_space, action_space=act_space,
                algorithm_name="aoc export", description=DESCRIPTION.format(
                    name=spec["corpus"]), jpeg_encoding=False)
            if progress is not None:
                progress(1, len(batches), "writing Minari episodes")
            for i, batch in enumerate(batches[1:], 2):
                dataset.storage.update_episodes(_buffers(data, batch, EpisodeBuffer))
                if progress is not None:
                    progress(i, len(batches), "writing Minari episodes")
            dataset.storage.update_metadata({"aoc": spec})
        os.replace(scratch / ident / "data", tmp / "data")
        shutil.rmtree(scratch)
    return [out]
