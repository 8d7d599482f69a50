"""SimplEx's Jacobian projection (aoc_cli.explanation.attribution): complete, and the path integral
of the gradient as finite differences compute it."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest
import torch

from aoc_cli.belief.model import BeliefNet, Encoder, Normalisation
from aoc_cli.explanation.attribution import (_belief, _double_net, encoded_inputs,
                                             jacobian_projection)
from aoc_cli.store import History

D_O, D_A, L = 3, 2, 2


def small_model(mode: str = "value"):
    """A small untrained belief network (seeded) with its encoder: the model's interface."""
    torch.manual_seed(0)
    net = BeliefNet(D_O, D_A, 1, L, hidden=16, belief_dim=4, use_action=mode == "value").eval()
    norm = Normalisation([0.5, -1.0, 2.0], [1.5, 0.5, 2.0], [0.0, 0.1], [1.0, 2.0], 0.3, 1.2,
                         [0.0], [1.0])
    enc = Encoder(norm, False, None, torch.device("cpu"))
    return SimpleNamespace(net=net, encoder=enc, mode=mode, history_length=L,
                           dims={"observation": D_O, "action_input": D_A}, discrete=False)


def rows(r: int = 5, seed: int = 1):
    rng = np.random.default_rng(seed)
    obs = rng.normal(size=(r, D_O)).astype(np.float32)
    act = rng.normal(size=(r, D_A)).astype(np.float32)
    mask = np.ones((r, L), bool)
    mask[0, 0] = False  # a row at its episode's second step
    hist = History(rng.normal(size=(r, L, D_O)).astype(np.float32),
                   rng.normal(size=(r, L, D_A)).astype(np.float32),
                   rng.normal(size=(r, L)).astype(np.float32), mask)
    return obs, act, hist


@pytest.mark.parametrize("mode", ["value", "imitation"])
def test_a_rows_attributions_sum_to_its_projection(mode):
    model = small_model(mode)
    obs, act, hist = rows()
    query = np.array([0.3, -0.2, 0.5, 0.1])
    res = jacobian_projection(model, query, obs, act, hist, nodes=128)
    net = _double_net(model)
    x = encoded_inputs(model, obs, act, hist)
    with torch.no_grad():
        h0 = _belief(net, *[None if v is None else torch.zeros_like(v[:1]) for v in x])[0]
        b = _belief(net, *x)
    shift = torch.as_tensor(query) - h0
    want = ((b - h0) @ shift / shift.dot(shift)).numpy()
    np.testing.assert_allclose(res["projection"], want, rtol=1e-12)
    total = sum(res[k].reshape(5, -1).sum(1) for k in ("observation", "action", "history")
                if res[k] is not None)
    np.testing.assert_allclose(res["completeness_gap"], np.abs(total - want), rtol=1e-9,
                               atol=1e-15)
    # the integration's accuracy: a small gap, smaller with more nodes
    assert np.all(res["completeness_gap"] <= 2e-3 * np.maximum(1.0, np.abs(want)))
    coarse = jacobian_projection(model, query, obs, act, hist, nodes=4)
    assert res["completeness_gap"].sum() < coarse["completeness_gap"].sum()
    assert (res["action"] is None) == (mode == "imitation")
    # the absent history step of row 0 is the baseline's: it contributes nothing
    assert np.all(res["history"][0, 0] == 0.0)


def test_attributions_agree_with_finite_differences_along_the_path():
    model = small_model("value")
    obs, act, hist = rows(r=2, seed=3)
    query = np.array([-0.4, 0.2, 0.6, -0.1])
    nodes = 8
    res = jacobian_projection(model, query, obs, act, hist, nodes=nodes)
    net = _double_net(model)
    x = [v.detach() for v in encoded_inputs(model, obs, act, hist)]
    with torch.no_grad():
        h0 = _belief(net, *[torch.zeros_like(v[:1]) for v in x])[0]
    shift = torch.as_tensor(query) - h0
    u = shift / shift.dot(shift)
    t, w = np.polynomial.legendre.leggauss(nodes)
    t, w = (t + 1) / 2, w / 2
    delta = 1e-6

    def score(parts):
        with torch.no_grad():
            return (_belief(net, *parts) @ u).numpy()

    for which, name in enumerate(("observation", "action", "history")):
        flat = x[which].reshape(2, -1)
        grads = np.zeros(flat.shape)
        for tk, wk in zip(t, w):
            for i in range(flat.shape[1]):
                up, down = [[tk * v for v in x] for _ in range(2)]
                e = torch.zeros_like(flat)
                e[:, i] = delta
                up[which] = up[which] + e.reshape(x[which].shape)
                down[which] = down[which] - e.reshape(x[which].shape)
                grads[:, i] += wk * (score(up) - score(down)) / (2 * delta)
        want = (flat.numpy() * grads).reshape(res[name].shape)
        np.testing.assert_allclose(res[name], want, rtol=1e-5, atol=1e-8)
