"""The training objective of the belief model: the loss and validation metric of one mode
(value: MSE and R^2; discrete imitation: cross-entropy and accuracy), with the optional
dynamics head. Shared by the in-memory training (:mod:`aoc_cli.belief.train`) and the
streaming one (:mod:`aoc_cli.belief.stream`)."""

from __future__ import annotations

import torch
from torch import nn


def _r2(out: torch.Tensor, y: torch.Tensor) -> float:
    """R^2, uniform average over the output dims."""
    sse = ((out - y) ** 2).sum(0)
    sst = ((y - y.mean(0)) ** 2).sum(0)
    r2 = torch.where(sst > 0, 1 - sse / sst.clamp_min(1e-12), torch.zeros_like(sst))
    return float(r2.mean())


class Objective:
    """Loss and validation metric of one mode, on encoded targets; with a dynamics weight,
    plus that weight times the squared error of the auxiliary head on the standardised o' - o
    (rows whose next observation is known only). Discrete imitation: the training loss may
    weight the actions (``class_weight`` (n,)) and smooth the labels; the validation metric is
    always the plain cross-entropy, so candidates of the model selection compare alike."""

    def __init__(self, mode: str, discrete: bool, dynamics_weight: float = 0.0,
                 dyn: torch.Tensor | None = None, dyn_valid: torch.Tensor | None = None,
                 class_weight: torch.Tensor | None = None, label_smoothing: float = 0.0):
        self.classify = mode == "imitation" and discrete
        self.weight = float(dynamics_weight) if dyn is not None else 0.0
        self.dyn, self.dyn_valid = dyn, dyn_valid
        self.class_weight, self.label_smoothing = class_weight, float(label_smoothing)

    def main_loss(self, out: torch.Tensor, y: torch.Tensor, train: bool = False) -> torch.Tensor:
        if self.classify:
            if train:
                return nn.functional.cross_entropy(out, y, weight=self.class_weight,
                                                   label_smoothing=self.label_smoothing)
            return nn.functional.cross_entropy(out, y)
        return nn.functional.mse_loss(out, y)

    def dynamics_loss(self, net, b: torch.Tensor, rows: torch.Tensor) -> torch.Tensor:
        err = ((net.dynamics(b) - self.dyn[rows]) ** 2).mean(1)
        valid = self.dyn_valid[rows]
        return (err * valid).sum() / valid.sum().clamp_min(1)

    def loss(self, net, b, out, y, rows) -> torch.Tensor:
        loss = self.main_loss(out, y, train=True)
        if self.weight > 0:
            loss = loss + self.weight * self.dynamics_loss(net, b, rows)
        return loss

    def metrics(self, net, b, out, y, rows) -> dict:
        """Loss, and R^2 or accuracy, on all of ``out``; ``dynamics_r2`` with the head."""
        main = self.main_loss(out, y)
        if self.classify:
            return {"loss": float(main), "accuracy": float((out.argmax(1) == y).float().mean())}
        result = {"loss": float(main), "r2": _r2(out, y)}
        if self.weight > 0:
            result["loss"] = float(main + self.weight * self.dynamics_loss(net, b, rows))
            keep = self.dyn_valid[rows]
            result["dynamics_r2"] = _r2(net.dynamics(b[keep]), self.dyn[rows][keep])
        return result
