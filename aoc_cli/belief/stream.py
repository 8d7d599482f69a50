"""Corpora beyond memory: training and beliefs a block of rows at a time.

The in-memory path (:mod:`aoc_cli.belief.train`) encodes every row once as tensors, which
needs several times the corpus's float arrays. Above :data:`STREAM_ROWS` rows training
streams instead, and the beliefs of every row are always written chunk by chunk:

* **Blocks.** The corpus rows are cut into blocks of about ``block_rows`` rows at episode
  boundaries. A block's columns are read from ``corpus.h5`` as contiguous slices, with the
  ``L`` rows before it, and encoded exactly as the in-memory path encodes them; each row's
  history window is built inside the block (:func:`block_inputs`). Peak memory grows with the
  block, not the corpus.
* **Training** (:func:`train_streaming`): each epoch visits the blocks in a random order and
  the training rows of a block (its training episodes) in a random order, in mini-batches of
  ``batch_size``. Validation uses the first validation episodes, up to
  :data:`VAL_ROWS_MAX` rows, kept in memory; the reported train loss is the epoch's running
  mean. Early stopping, the saved artefact and its metrics are as in the in-memory path. The
  value targets (N,) float64 are computed for every row, as they are saved with the model.
  The auxiliary dynamics head and the other belief kinds (critic, reward) are not streamed:
  they train in memory.
* **Beliefs** (:func:`write_row_beliefs`): computed in batches of 65536 rows, the same batches
  as :meth:`BeliefModel.row_beliefs`, and written into a memory-mapped ``.npy`` file
  (a temporary file renamed into place), so the (N, d_b) array is never held in memory.
"""

from __future__ import annotations

import math
import time
from pathlib import Path
from types import SimpleNamespace

import h5py
import numpy as np
import torch

from aoc_cli.belief.artefact import check_corpus, save_model
from aoc_cli.belief.censoring import censoring_of
from aoc_cli.belief.config import BeliefConfig
from aoc_cli.belief.data import EarlyStopping, report, split_episodes
from aoc_cli.belief.inputs import build_net, encode_corpus, network_dims, pick_device
from aoc_cli.belief.model import _STD_FLOOR, Encoder, Normalisation, _stats
from aoc_cli.belief.objective import Objective
from aoc_cli.belief.targets import value_spec, value_targets
from aoc_cli.errors import AocError, BadSetting, ModelExists, param
from aoc_cli.store import DEFAULT_MODEL, atomic_path, model_dir
from aoc_cli.store.layout import CORPUS_FILE
from aoc_cli.threads import thread_limits

#: Corpora with more rows than this train by streaming (when the model has no dynamics head).
STREAM_ROWS = 2_000_000
#: Rows per block read and encoded at once.
BLOCK_ROWS = 262_144
#: Validation rows kept in memory when streaming (the first validation episodes).
VAL_ROWS_MAX = 200_000
#: Rows per belief batch (as ``BeliefModel.row_beliefs`` and ``train.EVAL_BATCH``).
BELIEF_BATCH = 65_536


def streams(corpus, config: BeliefConfig) -> bool:
    """Whether ``train_model`` streams this corpus (module docstring)."""
    plain = config.mode == "imitation" or getattr(config, "belief", "value") == "value"
    return corpus.n_rows > STREAM_ROWS and plain and not config.dynamics_weight > 0


class Columns:
    """Contiguous row ranges of a corpus's float columns, read from ``corpus.h5``."""

    def __init__(self, corpus):
        self.path = Path(corpus.path) / CORPUS_FILE
        self.starts = np.asarray(corpus.episode_starts, dtype=np.int64)
        self.has_rewards = corpus.has_rewards
        self.n_rows = corpus.n_rows

    def read(self, a: int, b: int):
        """observations (b-a, d_o), actions (b-a, ...) and rewards (b-a,) or None."""
        with h5py.File(self.path, "r") as f:
            rew = f["rewards"][a:b] if self.has_rewards else None
            return f["observations"][a:b], f["actions"][a:b], rew

    def local_starts(self, lo: int, hi: int) -> np.ndarray:
        """Episode starts within rows [lo, hi), relative to lo, with 0 and hi - lo."""
        inside = self.starts[(self.starts > lo) & (self.starts < hi)] - lo
        return np.concatenate([[0], inside, [hi - lo]]).astype(np.int64)


def block_inputs(cols: Columns, encoder: Encoder, a: int, b: int, history_length: int,
                 use_action: bool, device: torch.device):
    """(inputs, offset): rows [a, b) encoded with their history windows; row r is local row
    r - offset of ``inputs`` (a :class:`aoc_cli.belief.inputs.CorpusInputs`)."""
    lo = max(0, a - history_length)
    obs, act, rew = cols.read(lo, b)
    view = SimpleNamespace(observations=obs, actions=act, rewards=rew,
                           episode_starts=cols.local_starts(lo, b))
    return encode_corpus(view, encoder, history_length, use_action, device), lo


def blocks(starts: np.ndarray, block_rows: int = BLOCK_ROWS) -> list[tuple[int, int]]:
    """Row ranges [a, b) of about ``block_rows`` rows, cut at episode starts."""
    out, a, n = [], 0, int(starts[-1])
    while a < n:
        j = np.searchsorted(starts, a + block_rows, side="left")
        b = int(starts[min(j, len(starts) - 1)])
        b = b if b > a else int(starts[np.searchsorted(starts, a, side="right")])
        out.append((a, b))
        a = b
    return out


def write_row_beliefs(model, corpus, path: str | Path, progress=None) -> Path:
    """Beliefs (N, d_b) float32 of every row written to the ``.npy`` file ``path`` in
    batches (module docstring); ``progress``: rows done (:mod:`aoc_cli.progress`)."""
    check_corpus(model, corpus)
    path = Path(path)
    n, cols = corpus.n_rows, Columns(corpus)
    with atomic_path(path, suffix=".npy") as tmp:
        out = np.lib.format.open_memmap(tmp, mode="w+", dtype=np.float32, shape=(n, model.d_b))
        with torch.no_grad():
            for a in range(0, n, BELIEF_BATCH):
                b = min(n, a + BELIEF_BATCH)
                inputs, lo = block_inputs(cols, model.encoder, a, b, model.history_length,
                                          model.mode == "value", model.device)
                rows = torch.arange(a - lo, b - lo, device=model.device)
                out[a:b] = model.net.belief(*inputs.batch(rows)).cpu().numpy()
                if progress is not None:
                    progress(b, n)
        out.flush()
        del out
    return path


# -- training -------------------------------------------------------------------------------

def _moments(cols: Columns, ranges, what: str, discrete: bool):
    """Exact mean and std (float64, chunked) of a column over the given row ranges."""
    total = sq = None
    count = 0
    with h5py.File(cols.path, "r") as f:
        ds = f[what]
        for a, b in ranges:
            x = np.asarray(ds[a:b], dtype=np.float64).reshape(b - a, -1)
            s = x.sum(0)
            total = s if total is None else total + s
            count += b - a
        mean = total / count
        for a, b in ranges:
            x = np.asarray(ds[a:b], dtype=np.float64).reshape(b - a, -1)
            d = ((x - mean) ** 2).sum(0)
            sq = d if sq is None else sq + d
    std = np.sqrt(sq / count)
    std = np.where(std > _STD_FLOOR, std, 1.0)
    return mean.tolist(), std.tolist()


def _normalisation(corpus, cols: Columns, ranges, discrete: bool, targets) -> Normalisation:
    o_mean, o_std = _moments(cols, ranges, "observations", False)
    a_mean = a_std = None
    if not discrete:
        a_mean, a_std = _moments(cols, ranges, "actions", False)
    r_mean, r_std = ([0.0], [1.0]) if not corpus.has_rewards else \
        _moments(cols, ranges, "rewards", False)
    t_mean = t_std = None
    if isinstance(targets, np.ndarray):  # the value targets, in memory (saved with the model)
        t_mean, t_std = _stats(targets.reshape(len(targets), -1))
    elif targets == "actions":
        t_mean, t_std = a_mean, a_std
    return Normalisation(o_mean, o_std, a_mean, a_std, r_mean[0], r_std[0], t_mean, t_std)


def block_value_targets(corpus, cols: Columns, ranges, value: str, gamma: float) -> np.ndarray:
    """(N,) float64 value targets computed block by block (whole episodes each): the same
    numbers as :func:`aoc_cli.belief.targets.value_targets`, which needs the whole rewards
    column and several (N,) float64 temporaries at once."""
    if value == "fqe" or censoring_of(corpus) is not None:  # across episodes: all at once
        return value_targets(corpus, value, gamma)
    out = np.empty(cols.n_rows, dtype=np.float64)
    key = "rewards" if value in ("return", "mean-return", "reward") else f"columns/{value}"
    try:
        with h5py.File(cols.path, "r") as f:
            ds = f[key] if key in f else None
            for a, b in ranges:
                part = None if ds is None else ds[a:b]
                view = SimpleNamespace(
                    name=corpus.name, has_rewards=corpus.has_rewards, manifest=corpus.manifest,
                    rewards=part if key == "rewards" else None,
                    episode_starts=cols.local_starts(a, b), column=lambda _name, p=part: p)
                out[a:b] = value_targets(view, value, gamma)
    except AocError:  # the whole column's check names the corpus row
        return value_targets(corpus, value, gamma)
    return out


def _episode_mask(starts: np.ndarray, episodes: np.ndarray, a: int, b: int) -> np.ndarray:
    """(b - a,) bool: rows of [a, b) that belong to ``episodes`` (sorted)."""
    first = np.searchsorted(starts, a, side="right") - 1
    last = np.searchsorted(starts, b - 1, side="right") - 1
    eps = np.arange(first, last + 1)
    keep = np.isin(eps, episodes)
    lengths = np.minimum(starts[eps + 1], b) - np.maximum(starts[eps], a)
    return np.repeat(keep, lengths)


def train_streaming(corpus, config: BeliefConfig, model_id: str = DEFAULT_MODEL,
                    overwrite: bool = False, progress=None, block_rows: int = BLOCK_ROWS,
                    save: bool = True, extra: dict | None = None) -> dict:
    """Train like :func:`aoc_cli.belief.train.train_model`, streaming blocks of rows
    (module docstring); writes the model (unless ``save`` is false) and returns its metrics
    (``extra`` merged in)."""
    started = time.perf_counter()
    if config.class_weight != "none" or config.label_smoothing > 0:
        raise BadSetting("class_weight" if config.class_weight != "none" else "label_smoothing",
                         config.class_weight if config.class_weight != "none"
                         else config.label_smoothing,
                         f"{param('class_weight')} and {param('label_smoothing')} are not "
                         f"available for corpora of over {STREAM_ROWS:,} rows (trained a block "
                         "at a time): train without them")
    if config.dynamics_weight > 0:
        raise AocError("the dynamics head is trained in memory, not streamed")
    if model_dir(corpus.path, model_id).exists() and not overwrite:
        raise ModelExists(corpus.name, model_id)
    cols = Columns(corpus)
    starts = cols.starts
    ranges = blocks(starts, block_rows)
    values = block_value_targets(corpus, cols, ranges, config.value, config.gamma) \
        if config.mode == "value" else None
    train_eps, val_eps = split_episodes(corpus.n_episodes, config.val_fraction, config.seed)
    device = pick_device(config.device)
    threads = config.resolved_threads()
    with thread_limits(torch=threads if device.type == "cpu" else None):
        return _train_streaming(corpus, config, model_id, cols, ranges, values, train_eps,
                                val_eps, device, threads, started, progress, save, extra)


def _train_streaming(corpus, config: BeliefConfig, model_id: str, cols: Columns, ranges,
                     values, train_eps, val_eps, device: torch.device, threads: int,
                     started: float, progress, save: bool, extra: dict | None) -> dict:
    """train_streaming's work, in its thread context."""
    starts = cols.starts
    dims = network_dims(corpus, config.mode)
    classify = config.mode == "imitation" and dims["discrete"]
    targets = values if config.mode == "value" else (None if classify else "actions")
    norm = _normalisation(corpus, cols, ranges, dims["discrete"], targets)
    encoder = Encoder(norm, dims["discrete"], dims["n_actions"], device)
    data = _Blocks(cols, ranges, encoder, config, dims["use_action"], classify, values,
                      device)
    val_parts = data.validation(val_eps)
    with torch.random.fork_rng(devices=[]):
        torch.manual_seed(config.seed)
        net = build_net(dims, config).to(device)
    stopping = _fit_streamed(net, data, val_parts, np.sort(train_eps), config, started,
                             progress)
    history, best = stopping.history, stopping.best
    net.load_state_dict(best["state"])
    net.eval()
    final = val_parts.metrics(net)
    n_train = int(np.diff(starts)[train_eps].sum())
    n_val = int(np.diff(starts)[val_eps].sum())
    metrics = {"model": model_id, "mode": config.mode, "epochs": len(history),
               "best_epoch": best["epoch"],
               "train_loss": history[best["epoch"] - 1]["train_loss"] if best["epoch"] else None,
               "val_loss": final["loss"], "streamed": True,
               "val_rows_scored": val_parts.n_rows}
    metrics.update({k if k.startswith("val_") else f"val_{k}": v
                    for k, v in final.items() if k != "loss"})
    metrics.update({"rows": corpus.n_rows, "train_rows": n_train, "val_rows": n_val,
                    "device": device.type, "threads": threads if device.type == "cpu" else None,
                    "belief": config.belief, "seconds": time.perf_counter() - started})
    metrics.update(extra or {})
    if not save:  # a candidate of the model selection: its metrics only
        return metrics
    save_model(corpus, model_id, net=net.cpu(), config=config, dims=dims, norm=norm,
               value=value_spec(config.value, config.gamma) if config.mode == "value" else None,
               values=values, metrics=metrics, history=history,
               split={"episodes": corpus.n_episodes, "val_episodes": len(val_eps),
                      "train_rows": n_train, "val_rows": n_val})
    return metrics


class _Blocks:
    """The corpus's blocks of rows ``ranges`` ([a, b) each), encoded on demand with their
    targets (the value targets ``values`` (N,), or the actions)."""

    def __init__(self, cols: Columns, ranges, encoder: Encoder, config: BeliefConfig,
                 use_action: bool, classify: bool, values, device: torch.device):
        self.cols, self.ranges, self.encoder, self.values = cols, ranges, encoder, values
        self.config, self.use_action, self.classify, self.device = (config, use_action,
                                                                    classify, device)
        self.objective = Objective(config.mode, encoder.discrete)

    def block(self, a: int, b: int, mask=None):
        """(inputs, local rows, targets) of the rows of [a, b) in ``mask`` ((b - a,) bool)."""
        cols, device = self.cols, self.device
        inputs, lo = block_inputs(cols, self.encoder, a, b, self.config.history_length,
                                  self.use_action, device)
        rows = np.arange(a, b) if mask is None else np.arange(a, b)[mask]
        if self.classify:
            with h5py.File(cols.path, "r") as f:
                y = torch.as_tensor(f["actions"][a:b][rows - a], device=device)
        elif self.config.mode == "value":
            y = self.encoder.targets(self.values[rows])
        else:
            with h5py.File(cols.path, "r") as f:
                y = self.encoder.targets(f["actions"][a:b][rows - a])
        return inputs, torch.as_tensor(rows - lo, device=device), y

    def validation(self, val_eps: np.ndarray) -> _Validation:
        """The first validation episodes, up to VAL_ROWS_MAX rows, encoded in memory."""
        starts = self.cols.starts
        lengths = np.diff(starts)[val_eps]
        kept = val_eps[:max(1, int(np.searchsorted(np.cumsum(lengths), VAL_ROWS_MAX, "right")))]
        parts = [self.block(int(starts[e]), int(starts[e + 1])) for e in kept]
        return _Validation(parts, self.objective)


class _Validation:
    """The validation rows kept in memory: (inputs, local rows, targets) per episode."""

    def __init__(self, parts: list, objective):
        self.parts, self.objective = parts, objective
        self.n_rows = int(sum(len(r) for _i, r, _y in parts))

    def metrics(self, net) -> dict:
        with torch.no_grad():
            outs = [net(*inp.batch(rows))[1] for inp, rows, _y in self.parts]
            ys = torch.cat([y for _i, _r, y in self.parts])
            return self.objective.metrics(net, None, torch.cat(outs), ys, None)


def _fit_streamed(net, data: _Blocks, val: _Validation, train_sorted: np.ndarray,
                  config: BeliefConfig, started: float, progress) -> EarlyStopping:
    """Adam epoch by epoch: the blocks in a random order, the training rows of a block (of the
    episodes ``train_sorted``) in a random order, until the validation loss stops improving."""
    optimiser = torch.optim.Adam(net.parameters(), lr=config.lr,
                                 weight_decay=config.weight_decay)
    rng = np.random.default_rng(config.seed)
    generator = torch.Generator().manual_seed(config.seed)
    starts, ranges, objective = data.cols.starts, data.ranges, data.objective
    n_batches = max(1, sum(math.ceil(int(_episode_mask(starts, train_sorted, a, b).sum())
                                     / config.batch_size) for a, b in ranges))
    stopping = EarlyStopping(net, config, started)
    for epoch in range(1, config.max_epochs + 1):
        net.train()
        total, count, done = 0.0, 0, 0
        for j in rng.permutation(len(ranges)):
            a, b = ranges[j]
            mask = _episode_mask(starts, train_sorted, a, b)
            if not mask.any():
                continue
            inputs, local, y = data.block(a, b, mask)
            perm = torch.randperm(len(local), generator=generator)
            for i in range(0, len(local), config.batch_size):
                pick = perm[i:i + config.batch_size]
                _beliefs, out = net(*inputs.batch(local[pick]))
                loss = objective.main_loss(out, y[pick])
                optimiser.zero_grad(set_to_none=True)
                loss.backward()
                optimiser.step()
                total += float(loss.detach()) * len(pick)
                count += len(pick)
                done += 1
            if progress is not None:
                report(progress, stopping.running(epoch, done, n_batches, total / count))
        net.eval()
        report(progress, stopping.end_epoch(net, epoch, total / max(count, 1), val.metrics(net),
                                            n_batches))
        if stopping.done:
            break
    return stopping
