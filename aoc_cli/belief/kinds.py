"""What a value-mode belief is trained on (``--belief``), beyond the paper's value regression.

* ``value``: b is trained to regress the chosen value v through the linear head l (the paper's
  equation); ``dynamics``: the same plus the auxiliary o' - o head (``--dynamics-weight``).
  Both are :func:`aoc_cli.belief.train.train_model`'s own loop.
* ``reward``: b is trained to regress the **immediate reward** r_t through a linear head (the
  reference code's "mb" world model: ``WorldModel_Hybrid``), in the same loop with r as its
  target; then l is refitted on the frozen beliefs to v (:func:`refit_value_head`).
* ``critic``: b is the last hidden layer of an offline TD3+BC critic
  (:mod:`aoc_cli.belief.critic`); l is fitted on the frozen beliefs to v
  (:func:`train_critic_model`).

For every kind the saved model is the same :class:`~aoc_cli.belief.model.BeliefNet` whose
``head`` maps the belief to v (standardised as the config's normalisation says), and
``values.npy`` holds v: the controller's v_hat = sum_c w_c v_c is a weighted sum of logged
values whatever the belief was trained on, and every loader works unchanged.
"""

from __future__ import annotations

import dataclasses
import time

import numpy as np
import torch

from aoc_cli.belief.artefact import save_model
from aoc_cli.belief.config import BeliefConfig
from aoc_cli.belief.critic import fit_critic
from aoc_cli.belief.data import report
from aoc_cli.belief.inputs import encode_corpus, network_dims, pick_device
from aoc_cli.belief.model import BeliefNet, Encoder, Normalisation
from aoc_cli.belief.targets import value_spec

#: Rows per forward pass when computing beliefs for the head fit.
_BATCH = 65536


def fit_head(beliefs: np.ndarray, targets: np.ndarray) -> tuple[np.ndarray, float]:
    """Least squares ``targets ~ beliefs @ w + c``: beliefs (R, d_b), targets (R,) ->
    w (d_b,) float64, c float (numpy's lstsq: minimum-norm where the beliefs are rank
    deficient, e.g. dead ReLU units)."""
    b = np.asarray(beliefs, dtype=np.float64)
    x = np.concatenate([b, np.ones((len(b), 1))], axis=1)
    coef, *_ = np.linalg.lstsq(x, np.asarray(targets, dtype=np.float64), rcond=None)
    return coef[:-1], float(coef[-1])


def _beliefs(net: BeliefNet, inputs, rows: np.ndarray, device) -> np.ndarray:
    out = []
    with torch.no_grad():
        for i in range(0, len(rows), _BATCH):
            r = torch.as_tensor(rows[i:i + _BATCH], device=device)
            out.append(net.belief(*inputs.batch(r)).cpu().double().numpy())
    return np.concatenate(out) if out else np.zeros((0, net.fc3.out_features))


def _mse_r2(pred: np.ndarray, y: np.ndarray) -> tuple[float, float]:
    sse = float(((pred - y) ** 2).sum())
    sst = float(((y - y.mean()) ** 2).sum()) if len(y) else 0.0
    return sse / max(1, len(y)), (1.0 - sse / sst) if sst > 0 else 0.0


def refit_value_head(net: BeliefNet, inputs, values: np.ndarray, train_rows: np.ndarray,
                     val_rows: np.ndarray, norm: Normalisation,
                     device) -> tuple[Normalisation, dict]:
    """Fit ``net.head`` on the frozen beliefs of ``train_rows`` to the standardised values
    (N,); returns the normalisation with v's target statistics and the head's metrics
    (``train_loss``, ``val_loss``: MSE in standardised units; ``val_r2``)."""
    v = np.asarray(values, dtype=np.float64)
    mean = float(v.mean())
    std = float(v.std()) if v.std() > 1e-6 else 1.0
    z = (v - mean) / std
    b_train = _beliefs(net, inputs, train_rows, device)
    w, c = fit_head(b_train, z[train_rows])
    with torch.no_grad():
        net.head.weight.copy_(torch.as_tensor(w[None, :], dtype=torch.float32))
        net.head.bias.fill_(c)
    b_val = _beliefs(net, inputs, val_rows, device)
    train_loss, _ = _mse_r2(b_train @ w + c, z[train_rows])
    val_loss, val_r2 = _mse_r2(b_val @ w + c, z[val_rows])
    norm = dataclasses.replace(norm, target_mean=[mean], target_std=[std])
    return norm, {"train_loss": train_loss, "val_loss": val_loss, "val_r2": val_r2}


def train_critic_model(corpus, config: BeliefConfig, model_id: str, data,
                       progress=None, extra: dict | None = None) -> dict:
    """``--belief critic``: train the critic for :meth:`BeliefConfig.critic_steps_for` steps
    (saved in the model's config), fit the head, write the model; final metrics (those of
    every model, plus ``val_td_loss``, ``val_q_mean`` and ``critic_steps_rule``; ``extra``
    merged in)."""
    started = time.perf_counter()
    steps, rule = config.critic_steps_for(corpus.n_rows, len(data.train_rows))
    config = dataclasses.replace(config, critic_steps=steps)
    device = pick_device(config.device)
    threads = config.resolved_threads()  # set by train_model for the training (aoc_cli.threads)
    dims = network_dims(corpus, "value")
    norm = Normalisation.fit(corpus.observations, corpus.actions, corpus.rewards,
                             dims["discrete"], data.values)
    encoder = Encoder(norm, dims["discrete"], dims["n_actions"], device)
    inputs = encode_corpus(corpus, encoder, config.history_length, True, device)

    def on_record(record):
        report(progress, {**record, "max_epochs": config.critic_steps, "batch": 1,
                          "batches": 1, "best_val_loss": None, "epoch_done": True}, "step")

    fit = fit_critic(corpus, inputs, encoder, config, data.train_rows, data.val_rows, device,
                     on_record=on_record)
    net = fit.critic.q1
    q_head = {"weight": net.head.weight.detach().cpu().double().numpy()[0].tolist(),
              "bias": float(net.head.bias.detach()), "reward_scale": fit.reward_scale}
    norm, head = refit_value_head(net, inputs, data.values, data.train_rows, data.val_rows,
                                  norm, device)
    last = fit.history[-1]
    metrics = {"model": model_id, "mode": "value", "epochs": config.critic_steps, "best_epoch": config.critic_steps,
               "train_loss": head["train_loss"], "val_loss": head["val_loss"],
               "val_r2": head["val_r2"], "val_td_loss": last["val_loss"],
               "val_q_mean": last["val_q_mean"], "rows": corpus.n_rows,
               "train_rows": len(data.train_rows), "val_rows": len(data.val_rows),
               "device": device.type, "threads": threads if device.type == "cpu" else None,
               "belief": "critic", "critic_steps_rule": rule, **(extra or {})}
    metrics["seconds"] = time.perf_counter() - started
    save_model(corpus, model_id, net=net.cpu(), config=config, dims=dims, norm=norm,
               value=value_spec(config.value, config.gamma), values=data.values,
               metrics=metrics, history=fit.history,
               split={"episodes": corpus.n_episodes, "val_episodes": len(data.val_episodes),
                      "train_rows": len(data.train_rows), "val_rows": len(data.val_rows)},
               extra={"critic": {"q_head": q_head, "steps": config.critic_steps,
                                 "bc_weight": config.critic_bc_weight}})
    return metrics
