"""A trained belief model on disk, ``<corpus>/models/<id>/``, and loaded for use.

Files (the folder is written in a temporary folder beside it and renamed into place):

* ``weights.pt``: the network's ``state_dict`` only (load with ``weights_only=True``);
* ``config.json``: the BeliefConfig, mode, value spec, normalisation, input dims, split,
  final metrics, and ``corpus_hash`` (the corpus the model was trained on);
* ``metrics.csv``: one line per epoch (train/validation loss, R^2 or accuracy, seconds);
* ``values.npy``: (N,) float64 the value target v of every corpus row (value mode only);
* ``neighbourhood.npy``: (N,) float64 rule 7's values of the rows, FQE over the log's
  neighbourhoods (only where ``aoc train`` decided rule 7; ``config.json`` ``neighbourhood``
  says by which distance: ``l2``, or ``measured cells`` on a corpus with filled gaps);
* ``neighbourhood_space.npy``: (N, d_o) float32 the log's rows denoised and standardised, the
  space of rule 7's sets (``config.json`` ``neighbourhood``: ``scale``, ``centre``,
  ``radius``, and the sets' sizes ``set_rows``), so that a controller builds them without
  denoising the log again.
"""

from __future__ import annotations

import csv
import hashlib
import json
import time
from pathlib import Path
from typing import NamedTuple

import numpy as np
import torch

from aoc_cli.belief.config import BeliefConfig
from aoc_cli.belief.inputs import build_net, encode_corpus, pick_device
from aoc_cli.belief.model import BeliefNet, Encoder, Normalisation
from aoc_cli.errors import AocError, ModelMissing, ModelStale, call, param
from aoc_cli.index.search.neighbourhood import SETS, measured_cells
from aoc_cli.store import (DEFAULT_MODEL, History, atomic_dir, file_record, model_dir, seal,
                           write_json, write_npy)
from aoc_cli.store.verify import check_files, read_json

FORMAT = "aoc-belief-model"
FORMAT_VERSION = 1


def list_models(corpus) -> list[str]:
    """Ids of the models of ``corpus``, oldest first (by training time)."""
    root = Path(corpus.models_dir)
    if not root.is_dir():
        return []
    found = []
    for p in root.iterdir():
        if p.name.startswith(".") or not (p / "config.json").is_file():
            continue
        try:
            trained = float(json.loads((p / "config.json").read_text()).get("trained_unix", 0.0))
        except (OSError, ValueError, TypeError, AttributeError):
            trained = 0.0  # a damaged config: listed, so that loading it says it is damaged
        found.append((trained, p.name))
    return [name for _t, name in sorted(found)]


def save_model(corpus, model_id: str, *, net: BeliefNet, config: BeliefConfig, dims: dict,
               norm: Normalisation, value: dict | None, values: np.ndarray | None,
               metrics: dict, history: list[dict], split: dict,
               dynamics_target: dict | None = None, extra: dict | None = None,
               neighbourhood: np.ndarray | None = None, space: dict | None = None) -> Path:
    """Write the model folder atomically (replacing any previous one of that id).
    ``dynamics_target``: the standardisation {"mean", "std"} (d_o,) of the auxiliary head's
    target o' - o, when the model has the head; ``extra``: more JSON entries of config.json
    (e.g. the critic's Q head, ``--belief critic``); ``neighbourhood``: rule 7's row values;
    ``space``: what their sets were built from (:meth:`~aoc_cli.index.search.neighbourhood.
    Neighbourhood.space`) and their sizes (``set_rows``)."""
    path = model_dir(corpus.path, model_id)
    meta = {
        "format": FORMAT, "format_version": FORMAT_VERSION,
        "model": model_id, "corpus": corpus.name, "corpus_hash": corpus.hash,
        "trained": time.strftime("%Y-%m-%dT%H:%M:%S%z"), "trained_unix": time.time(),
        "mode": config.mode, "value": value, "config": config.to_dict(), "dims": dims,
        "normalisation": norm.to_dict(), "split": split, "metrics": metrics,
    }
    if dynamics_target is not None:
        meta["dynamics_target"] = {k: np.asarray(v, dtype=float).tolist()
                                   for k, v in dynamics_target.items()}
    if neighbourhood is not None:   # the distance rule 7's rows were found by
        meta["neighbourhood"] = {"distance": "l2" if measured_cells(corpus) is None
                                 else "measured cells", "sets": SETS}
        if space is not None:
            meta["neighbourhood"].update(
                {k: np.asarray(space[k], float).tolist() for k in ("scale", "centre")},
                radius=float(space["radius"]), set_rows=space.get("set_rows"))
    meta.update(extra or {})
    with atomic_dir(path) as tmp:
        torch.save({k: v.detach().cpu() for k, v in net.state_dict().items()},
                   tmp / "weights.pt")
        if values is not None:
            write_npy(tmp / "values.npy", np.asarray(values, dtype=np.float64))
        if neighbourhood is not None:
            write_npy(tmp / "neighbourhood.npy", np.asarray(neighbourhood, dtype=np.float64))
        if neighbourhood is not None and space is not None:
            write_npy(tmp / "neighbourhood_space.npy",
                      np.asarray(space["denoised"], dtype=np.float32))
        columns = list(dict.fromkeys(k for r in history for k in r))
        with open(tmp / "metrics.csv", "w", newline="") as f:
            writer = csv.DictWriter(f, fieldnames=columns, lineterminator="\n")
            writer.writeheader()
            writer.writerows(history)
        meta["files"] = {p.name: file_record(p) for p in sorted(tmp.iterdir())}
        write_json(tmp / "config.json", seal(meta))  # sealed: `aoc verify` checks every byte
    return path


class LinearHead(NamedTuple):
    """The linear head l in original units: ``output = belief @ weight.T + bias``.

    weight (out, d_b) float64, bias (out,) float64; out = 1 (value), d_a (continuous actions)
    or n (discrete logits).
    """

    weight: np.ndarray
    bias: np.ndarray


class BeliefModel:
    """A trained belief function b and head l, ready for batched inference."""

    def __init__(self, path: Path, meta: dict, net: BeliefNet, values: np.ndarray | None,
                 device: torch.device):
        self.path = Path(path)
        self.meta = meta
        self.id = meta["model"]
        self.config = BeliefConfig.from_dict(meta["config"], strict=False)
        self.mode: str = meta["mode"]
        self.dims: dict = meta["dims"]
        self.corpus_hash: str = meta["corpus_hash"]
        self.values = values
        #: (N,) rule 7's values of the rows (``neighbourhood.npy``), or None
        self.neighbourhood_values: np.ndarray | None = None
        #: what rule 7's sets were built from (``neighbourhood_space.npy`` and config.json's
        #: ``neighbourhood``), or None
        self.neighbourhood_space: dict | None = None
        self.net = net.eval()
        self._hash: tuple | None = None  # (weights' versions, hash): see ``hash``
        self.device = device
        self.encoder = Encoder(Normalisation.from_dict(meta["normalisation"]),
                               self.dims["discrete"], self.dims["n_actions"], device)

    @property
    def d_b(self) -> int:
        return int(self.config.belief_dim)

    @property
    def history_length(self) -> int:
        return int(self.config.history_length)

    @property
    def discrete(self) -> bool:
        return bool(self.dims["discrete"])

    @property
    def hash(self) -> str:
        """blake2b of the weights and the config: what an index built from this model records.
        Computed once and kept while the weights are unchanged (torch counts every in-place
        change of a tensor in its ``_version``; a loaded model's weights do not change)."""
        versions = tuple(t._version for t in self.net.state_dict(keep_vars=True).values())
        if self._hash is None or self._hash[0] != versions:
            self._hash = (versions, self._weights_hash())
        return self._hash[1]

    def _weights_hash(self) -> str:
        h = hashlib.blake2b(digest_size=16)
        for key, tensor in sorted(self.net.state_dict().items()):
            arr = tensor.detach().cpu().numpy()
            h.update(f"{key}{arr.dtype.str}{arr.shape}".encode())
            h.update(np.ascontiguousarray(arr).tobytes())
        stable = {k: self.meta[k] for k in ("mode", "value", "config", "dims", "normalisation",
                                             "corpus_hash")}
        h.update(json.dumps(stable, sort_keys=True).encode())
        return h.hexdigest()

    @property
    def head_weights(self) -> LinearHead:
        """The head in original units (value, action, or logits): see :class:`LinearHead`."""
        w = self.net.head.weight.detach().cpu().double().numpy()
        b = self.net.head.bias.detach().cpu().double().numpy()
        if self.encoder.t_std is not None:
            std = self.encoder.t_std.cpu().double().numpy()
            mean = self.encoder.t_mean.cpu().double().numpy()
            w, b = w * std[:, None], b * std + mean
        return LinearHead(w, b)

    def predicted_change(self, beliefs: np.ndarray) -> np.ndarray:
        """The auxiliary dynamics head's prediction of o' - o, (Q, d_o) float64 in original
        units, from beliefs (Q, d_b) (a model trained with ``--dynamics-weight`` > 0)."""
        target = self.meta.get("dynamics_target")
        if self.net.dynamics is None or target is None:
            raise AocError(f"model {self.id!r} has no dynamics head: train it with "
                           f"{param('dynamics_weight')} > 0 (a model of an earlier version: "
                           "retrain it)")
        with torch.no_grad():
            b = torch.as_tensor(np.asarray(beliefs, dtype=np.float32), device=self.device)
            z = self.net.dynamics(b).cpu().double().numpy()
        return z * np.asarray(target["std"]) + np.asarray(target["mean"])

    # -- inference -------------------------------------------------------------------------
    def _inputs(self, observations, actions, history: History | None):
        obs = np.asarray(observations)
        if obs.ndim == 1:
            obs = obs[None, :]
        d_o = self.dims["observation"]
        if obs.ndim != 2 or obs.shape[1] != d_o:
            raise AocError(f"observations must be (Q, {d_o}), got shape {obs.shape}")
        q = len(obs)
        act = None
        if self.mode == "value":
            if actions is None:
                raise AocError("a value-mode belief model needs the actions (Q, d_a)")
            act = np.asarray(actions)
            if self.discrete and act.ndim == 2 and act.shape[1] == 1:
                act = act[:, 0]
            if self.discrete and act.ndim == 0:
                act = act[None]
            if not self.discrete and act.ndim == 1:
                act = act[:, None] if self.dims["action"] == 1 else act[None, :]
            q = max(q, len(act))
        steps = None
        L = self.history_length
        if L > 0:
            if history is None:
                raise AocError(f"this belief model needs a history of length {L}")
            if history.mask.shape[1] < L:
                raise AocError(f"history of length {history.mask.shape[1]} given, the model "
                               f"was trained with {param('history_length', L)}")
            h = [np.asarray(x)[:, -L:] for x in history]
            steps = self.encoder.steps(*h)
            q = max(q, len(steps))
        parts = [self.encoder.observations(obs),
                 None if act is None else self.encoder.actions(act), steps]
        for p in parts:  # a leading dimension of 1 broadcasts (one observation, K candidates)
            if p is not None and len(p) not in (1, q):
                raise AocError(f"inputs have different row counts ({len(p)} vs {q})")
        return parts, q

    def beliefs(self, observations, actions=None, history: History | None = None,
                batch: int = 65536) -> np.ndarray:
        """(Q, d_b) float32 beliefs of observations (Q, d_o), actions (Q, d_a) or (Q,) int
        (value mode; ignored in imitation mode) and their histories (R = Q or 1)."""
        return self._run(observations, actions, history, batch)[0]

    def predict(self, observations, actions=None, history: History | None = None,
                batch: int = 65536) -> np.ndarray:
        """Head outputs in original units: value (Q,), actions (Q, d_a) or logits (Q, n)."""
        out = self._run(observations, actions, history, batch)[1]
        return out[:, 0] if self.mode == "value" else out

    def _run(self, observations, actions, history, batch):
        (obs, act, steps), q = self._inputs(observations, actions, history)
        obs, act = (None if p is None else p.expand(q, *p.shape[1:]) for p in (obs, act))
        beliefs, outs = [], []
        with torch.no_grad():
            # one history for every row (a control step's K candidates): the GRU runs once
            shared = self.net.memory(steps) if steps is not None and len(steps) == 1 else None
            for i in range(0, q, batch):
                sl = slice(i, i + batch)
                n = len(obs[sl])
                memory = shared.expand(n, -1) if shared is not None \
                    else None if steps is None else self.net.memory(steps[sl])
                b = self.net.belief_from_memory(memory, obs[sl], None if act is None else act[sl])
                out = self.net.head(b)
                if self.encoder.t_std is not None:
                    out = self.encoder.untarget(out)
                beliefs.append(b.cpu().numpy().astype(np.float32))
                outs.append(out.cpu().double().numpy())
        if not beliefs:
            return (np.zeros((0, self.d_b), np.float32),
                    np.zeros((0, self.dims["output"]), np.float64))
        return np.concatenate(beliefs), np.concatenate(outs)

    def row_beliefs(self, corpus, batch: int = 65536, progress=None) -> np.ndarray:
        """(N, d_b) float32 beliefs of every corpus row (its own observation, action, history).

        ``progress(done_rows, total_rows)`` is called after each batch when given.
        """
        check_corpus(self, corpus)
        inputs = encode_corpus(corpus, self.encoder, self.history_length,
                               self.mode == "value", self.device)
        n = corpus.n_rows
        out = np.empty((n, self.d_b), np.float32)
        with torch.no_grad():
            for i in range(0, n, batch):
                rows = torch.arange(i, min(n, i + batch), device=self.device)
                out[i:i + len(rows)] = self.net.belief(*inputs.batch(rows)).cpu().numpy()
                if progress is not None:
                    progress(i + len(rows), n)
        return out


def check_corpus(model: BeliefModel, corpus) -> None:
    """Refuse a model trained on other data than ``corpus`` holds now."""
    if model.corpus_hash != corpus.hash:
        raise ModelStale(corpus.name, model.id, model.corpus_hash, corpus.hash)


def load_model(corpus, model_id: str | None = None, device: str | None = None) -> BeliefModel:
    """Load model ``model_id`` of ``corpus`` (None: ``default`` when it exists, else the only
    one, else the latest trained) onto ``device`` (None: ``auto``, a GPU when torch sees one).
    The device the model was trained on is a training setting, not the model's: a model
    trained on a GPU machine runs on one without."""
    ids = list_models(corpus)
    if model_id is None:
        if not ids:
            raise ModelMissing(corpus.name, None)
        model_id = DEFAULT_MODEL if DEFAULT_MODEL in ids else ids[-1]
    path = model_dir(corpus.path, model_id)
    if not path.is_dir():
        raise ModelMissing(corpus.name, model_id, ids)
    what = f"model {model_id!r} of corpus {corpus.name!r} is damaged"
    todo = f"re-run `{call('train', corpus.name, model=model_id, overwrite=True)}`"
    meta = read_json(path / "config.json", what, todo)
    if meta.get("format") != FORMAT or meta.get("format_version") != FORMAT_VERSION:
        raise AocError(f"model {model_id!r} of corpus {corpus.name!r} has an unknown format: "
                       f"{todo}")
    check_files(path, meta, ("weights.pt", "values.npy", "neighbourhood.npy",
                             "neighbourhood_space.npy"), what, todo)
    try:
        dev = pick_device(device or "auto")
        net = build_net(meta["dims"], BeliefConfig.from_dict(meta["config"], strict=False))
        state = torch.load(path / "weights.pt", map_location="cpu", weights_only=True)
        net.load_state_dict(state)
        values = None
        if (path / "values.npy").is_file():
            values = np.load(path / "values.npy", allow_pickle=False)
        hood = (np.load(path / "neighbourhood.npy", allow_pickle=False)
                if (path / "neighbourhood.npy").is_file() else None)
        space = None
        if hood is not None and (path / "neighbourhood_space.npy").is_file():
            made = meta["neighbourhood"]
            space = {"scale": np.asarray(made["scale"], np.float64),
                     "centre": np.asarray(made["centre"], np.float64),
                     "radius": float(made["radius"]),
                     "denoised": np.load(path / "neighbourhood_space.npy", allow_pickle=False)}
    except AocError:
        raise
    except Exception as err:  # a truncated zip, a bad .npy header, keys or shapes that differ
        first = str(err).strip().splitlines()[0][:160] if str(err).strip() else ""
        raise AocError(f"{what}: reading {path} failed ({type(err).__name__}: {first}); "
                       f"{todo}") from None
    model = BeliefModel(path, meta, net.to(dev), values, dev)
    model.neighbourhood_values = hood
    model.neighbourhood_space = space
    check_corpus(model, corpus)
    return model
