"""Training the belief model: episode split, precomputed inputs, Adam, early stopping.

The inputs are encoded once (:mod:`aoc_cli.belief.inputs`), so a mini-batch is three gathers.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import torch

from aoc_cli.belief.artefact import save_model
from aoc_cli.belief.config import BeliefConfig
from aoc_cli.belief.data import EarlyStopping, TrainingData, prepare, report
from aoc_cli.belief.inputs import (CorpusInputs, build_net, encode_corpus, network_dims,
                                   pick_device)
from aoc_cli.belief.kinds import refit_value_head, train_critic_model
from aoc_cli.belief.model import Encoder, Normalisation
from aoc_cli.belief.objective import Objective
from aoc_cli.belief.stream import streams, train_streaming
from aoc_cli.belief.targets import value_spec
from aoc_cli.store import DEFAULT_MODEL
from aoc_cli.threads import thread_limits

#: Rows per forward pass when evaluating (no gradients).
EVAL_BATCH = 65536


def dynamics_targets(corpus) -> tuple[np.ndarray, np.ndarray]:
    """The auxiliary target o' - o: (N, d_o) float64 and (N,) bool, false on each episode's
    last row (its next observation is not in the corpus)."""
    obs = np.asarray(corpus.observations, dtype=np.float64)
    delta = np.zeros_like(obs)
    delta[:-1] = obs[1:] - obs[:-1]
    valid = np.ones(len(obs), dtype=bool)
    valid[np.asarray(corpus.episode_starts[1:], dtype=np.int64) - 1] = False
    delta[~valid] = 0.0
    return delta, valid


def class_weights(actions: np.ndarray, n_actions: int) -> np.ndarray:
    """(n_actions,) ``balanced`` weights N / (n_actions * N_a) of discrete actions (N,); an
    action absent from ``actions`` gets weight 0."""
    counts = np.bincount(np.asarray(actions, dtype=np.int64), minlength=n_actions)
    return np.where(counts > 0, len(actions) / (n_actions * np.maximum(counts, 1)), 0.0)


def _evaluate(net, inputs: CorpusInputs, rows: torch.Tensor, y: torch.Tensor, objective) -> dict:
    beliefs, outs = [], []
    with torch.no_grad():
        for i in range(0, len(rows), EVAL_BATCH):
            b, out = net(*inputs.batch(rows[i:i + EVAL_BATCH]))
            beliefs.append(b)
            outs.append(out)
        return objective.metrics(net, torch.cat(beliefs), torch.cat(outs), y, rows)


def train_model(corpus, config: BeliefConfig, model_id: str = DEFAULT_MODEL,
                overwrite: bool = False, progress=None, prepared: TrainingData | None = None, save: bool = True,
                extra: dict | Callable[[], dict] | None = None, inspect=None) -> dict:
    """Learn b and l on ``corpus`` and write ``corpus.models_dir/<model_id>/``; final metrics.

    ``progress`` (:mod:`aoc_cli.progress`): the epochs done of ``max_epochs``, every few
    batches and at the end of every epoch, labelled with the batch and the running train,
    validation and best validation losses (the per-epoch records are the saved ``history``).
    ``save=False`` trains and returns the
    metrics without writing the model; ``extra`` is merged into the saved metrics (a dict, or a
    function giving it, called once ``inspect`` ran: aoc_cli.training.record). ``prepared`` is the
    result of :func:`aoc_cli.belief.data.prepare` for the same arguments, when already known.
    ``inspect(net, inputs, data, norm)``, when given, is called with the trained network (best
    weights, eval mode), the encoded corpus, the split and the inputs' normalisation; its dict
    is merged into the metrics (the model selection's validation of the decomposition,
    aoc_cli.training.tuning; the held-out epsilon rule, aoc_cli.training.epsilon_rule).
    """
    if streams(corpus, config):  # a large corpus: trained a block of rows at a time
        return train_streaming(corpus, config, model_id, overwrite, progress, save=save,
                               extra=_entries(extra))
    started = time.perf_counter()
    data = prepared or prepare(corpus, config, model_id, overwrite)
    device = pick_device(config.device)
    threads = config.resolved_threads()
    with thread_limits(torch=threads if device.type == "cpu" else None):
        if config.belief == "critic":  # its own training (aoc_cli.belief.kinds)
            return train_critic_model(corpus, config, model_id, data, progress,
                                      _entries(extra))
        return _train(corpus, config, model_id, data, device, threads, started, progress, save,
                      extra, inspect)


def _entries(extra: dict | Callable[[], dict] | None) -> dict:
    """The entries ``extra`` gives the metrics: a dict, or what a function of none returns."""
    return (extra() if callable(extra) else extra) or {}


def _train(corpus, config: BeliefConfig, model_id: str, data: TrainingData,
           device: torch.device, threads: int, started: float, progress, save: bool,
           extra: dict | Callable[[], dict] | None, inspect=None) -> dict:
    """train_model's in-memory path, in its thread context."""
    problem = _Problem.build(corpus, config, data.values, device)
    with torch.random.fork_rng(devices=[]):
        torch.manual_seed(config.seed)
        net = build_net(problem.dims, config).to(device)
    tr = torch.as_tensor(data.train_rows, device=device)
    va = torch.as_tensor(data.val_rows, device=device)
    stopping = _fit(net, problem, tr, va, config, started, progress)

    net.load_state_dict(stopping.best["state"])
    net.eval()
    metrics = _final_metrics(net, problem, tr, va, corpus, config, model_id, stopping)
    if inspect is not None:
        metrics.update(inspect(net, problem.inputs, data, problem.norm))
    if config.belief == "reward":
        problem.norm, head = refit_value_head(net, problem.inputs, data.values, data.train_rows,
                                              data.val_rows, problem.norm, device)
        metrics["val_reward_r2"] = metrics.pop("val_r2")
        metrics.update(head)
    metrics.update({"rows": corpus.n_rows, "train_rows": len(data.train_rows),
                    "val_rows": len(data.val_rows), "device": device.type,
                    "threads": threads if device.type == "cpu" else None,
                    "belief": config.belief})
    metrics["seconds"] = time.perf_counter() - started
    metrics.update(_entries(extra))  # e.g. the settings chosen (aoc_cli.training.tuning)
    if not save:  # a candidate of the model selection: its metrics only
        return metrics
    save_model(corpus, model_id, net=net.cpu(), config=config, dims=problem.dims,
               norm=problem.norm,
               value=value_spec(config.value, config.gamma) if config.mode == "value" else None,
               values=data.values, metrics=metrics, history=stopping.history,
               split={"episodes": corpus.n_episodes, "val_episodes": len(data.val_episodes),
                      "train_rows": len(data.train_rows), "val_rows": len(data.val_rows)},
               dynamics_target=problem.dynamics_standard, neighbourhood=data.neighbourhood,
               space=data.space)
    return metrics


@dataclass
class _Problem:
    """What the network is fitted to, encoded once on ``device``.

    dims: the network's sizes (:func:`aoc_cli.belief.inputs.network_dims`, with ``dynamics``
    when the auxiliary head is trained). classify: imitation of discrete actions.
    norm, inputs: the fitted normalisation and every row's encoded inputs.
    targets: (N, ...) the encoded targets (class ids when classifying).
    objective: the loss and validation metrics. dynamics_standard: mean and std of o' - o
    (saved with the model) or None.
    """

    dims: dict
    classify: bool
    norm: Normalisation
    inputs: CorpusInputs
    targets: torch.Tensor
    objective: Objective
    dynamics_standard: dict | None

    @classmethod
    def build(cls, corpus, config: BeliefConfig, values, device: torch.device) -> _Problem:
        dims = network_dims(corpus, config.mode)
        if config.mode == "value" and config.dynamics_weight > 0:
            dims["dynamics"] = dims["observation"]
        classify = config.mode == "imitation" and dims["discrete"]
        if config.mode == "value":  # --belief reward: trained on r, head refitted to v later
            targets = corpus.rewards if config.belief == "reward" else values
        else:
            targets = None if classify else corpus.actions
        norm = Normalisation.fit(corpus.observations, corpus.actions, corpus.rewards,
                                 dims["discrete"], targets)
        encoder = Encoder(norm, dims["discrete"], dims["n_actions"], device)
        inputs = encode_corpus(corpus, encoder, config.history_length, dims["use_action"], device)
        y_all = torch.as_tensor(corpus.actions, device=device) if classify \
            else encoder.targets(targets)
        dyn = dyn_valid = dyn_standard = None
        if dims.get("dynamics", 0) > 0:
            dyn, dyn_valid, dyn_standard = _standard_dynamics(corpus, device)
        cw = None
        if classify and config.class_weight == "balanced":
            cw = torch.as_tensor(class_weights(corpus.actions, dims["n_actions"]),
                                 dtype=torch.float32, device=device)
        objective = Objective(config.mode, dims["discrete"], config.dynamics_weight, dyn,
                               dyn_valid, class_weight=cw,
                               label_smoothing=config.label_smoothing if classify else 0.0)
        return cls(dims, classify, norm, inputs, y_all, objective, dyn_standard)


def _standard_dynamics(corpus, device: torch.device):
    """The auxiliary target o' - o standardised: (N, d_o) float32 tensor, (N,) bool tensor of
    the rows that have one, and the ``{"mean", "std"}`` used."""
    delta, valid = dynamics_targets(corpus)
    mean, std = (delta[valid].mean(0), delta[valid].std(0)) if valid.any() \
        else (np.zeros(delta.shape[1]), np.ones(delta.shape[1]))
    std = np.where(std > 1e-6, std, 1.0)
    dyn = torch.as_tensor((delta - mean) / std, dtype=torch.float32, device=device)
    dyn_valid = torch.as_tensor(valid, dtype=torch.float32, device=device).bool()
    return dyn, dyn_valid, {"mean": mean, "std": std}


def _fit(net, problem: _Problem, tr: torch.Tensor, va: torch.Tensor, config: BeliefConfig,
         started: float, progress) -> EarlyStopping:
    """Adam on mini-batches of the training rows ``tr``, epoch by epoch, until the validation
    loss on ``va`` stops improving (:class:`aoc_cli.belief.data.EarlyStopping`, returned)."""
    inputs, y_all, objective = problem.inputs, problem.targets, problem.objective
    optimiser = torch.optim.Adam(net.parameters(), lr=config.lr,
                                 weight_decay=config.weight_decay)
    generator = torch.Generator().manual_seed(config.seed)
    y_val = y_all[va]
    n_batches = max(1, math.ceil(len(tr) / config.batch_size))
    report_every = max(1, n_batches // 20)

    stopping = EarlyStopping(net, config, started)
    for epoch in range(1, config.max_epochs + 1):
        net.train()
        perm = tr[torch.randperm(len(tr), generator=generator).to(tr.device)]
        total, count = 0.0, 0
        for b in range(n_batches):
            rows = perm[b * config.batch_size:(b + 1) * config.batch_size]
            beliefs, out = net(*inputs.batch(rows))
            loss = objective.loss(net, beliefs, out, y_all[rows], rows)
            optimiser.zero_grad(set_to_none=True)
            loss.backward()
            optimiser.step()
            total += float(loss.detach()) * len(rows)
            count += len(rows)
            if progress is not None and (b + 1) % report_every == 0 and b + 1 < n_batches:
                report(progress, stopping.running(epoch, b + 1, n_batches, total / count))
        net.eval()
        val = _evaluate(net, inputs, va, y_val, objective)
        report(progress, stopping.end_epoch(net, epoch, total / count, val, n_batches))
        if stopping.done:
            break
    return stopping


def _final_metrics(net, problem: _Problem, tr: torch.Tensor, va: torch.Tensor, corpus,
                   config: BeliefConfig, model_id: str, stopping: EarlyStopping) -> dict:
    """The trained (best) network's loss and R^2 or accuracy on the training and validation
    rows, with the epochs run."""
    inputs, y_all, objective = problem.inputs, problem.targets, problem.objective
    final_train = _evaluate(net, inputs, tr, y_all[tr], objective)
    final_val = _evaluate(net, inputs, va, y_all[va], objective)
    metrics = {"model": model_id, "mode": config.mode, "epochs": len(stopping.history),
               "best_epoch": stopping.best["epoch"], "train_loss": final_train["loss"],
               "val_loss": final_val["loss"]}
    if problem.classify:
        val_rows = va.cpu().numpy()
        majority = np.bincount(corpus.actions[val_rows], minlength=problem.dims["n_actions"]).max()
        metrics["val_accuracy"] = final_val["accuracy"]
        metrics["val_majority_accuracy"] = float(majority / len(val_rows))
    else:
        metrics["val_r2"] = final_val["r2"]
        if "dynamics_r2" in final_val:
            metrics["val_dynamics_r2"] = final_val["dynamics_r2"]
    return metrics
