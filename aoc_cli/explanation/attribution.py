"""Which input features made a supporting row count: SimplEx's Jacobian projection.

SimplEx (Crabbe et al., "Explaining Latent Representations with a Corpus of Examples",
NeurIPS 2021, section 2.3) explains how a corpus example's latent representation contributes
to a query's: for the belief function g (here b), a baseline input x0 and a corpus row's input
x^c, the contribution of input feature i is

    j^c_i = (x^c_i - x0_i) * integral_0^1 dg/dx_i (x0 + t (x^c - x0)) dt        in R^{d_b},

and its projection on the query's belief y, measured from the baseline's belief h0 = g(x0),

    p^c_i = < j^c_i, y - h0 > / ||y - h0||^2.

By the gradient theorem sum_i j^c_i = b^c - h0 (completeness), so a row's attributions sum to
its *projection* p^c = <b^c - h0, y - h0> / ||y - h0||^2: how far the row's belief points where
the query's does, 1 for a row whose belief is the query's. In the decomposition y ~ sum_c w^c
b^c, so sum_c w^c p^c ~ 1 (exactly for a query inside the hull).

Here the input x of a row is the network's standardised input: the observation (d_o), the
action (d_a_in, value mode) and the history steps (L, F), F = d_o + d_a_in + 2 (observation,
action, reward, present); the baseline x0 is all zeros: the corpus's mean observation, no
action, no history (every step absent). The integral is Gauss-Legendre quadrature in t
(``nodes`` points); the projection needs one vector-Jacobian product per node (the gradient of
<g(x(t)), y - h0>), all rows and nodes in one batched backward pass of the network in float64
(torch.autograd). ``completeness_gap`` reports |sum_i p^c_i - p^c|, the integration's error (the
network is piecewise smooth: ReLU layers; more nodes, smaller gap).
"""

from __future__ import annotations

import copy

import numpy as np
import torch

from aoc_cli.store import History

#: Gauss-Legendre nodes of the path integral (the gap is reported per row).
NODES = 32


def _double_net(model):
    """A float64 copy of the model's network, kept on the model (evaluation mode)."""
    net = getattr(model, "_attribution_net", None)
    if net is None:
        net = copy.deepcopy(model.net).double().eval()
        model._attribution_net = net
    return net


def encoded_inputs(model, observations: np.ndarray, actions, history: History | None):
    """The network's standardised inputs of R rows as float64 tensors: obs (R, d_o), act
    (R, d_a_in) or None (imitation), steps (R, L, F) or None (L = 0)."""
    enc = model.encoder
    obs = enc.observations(np.asarray(observations, np.float32)).double()
    act = None
    if model.mode == "value":
        act = enc.actions(np.asarray(actions)).double()
        if act.ndim == 1:
            act = act[:, None]
    steps = None
    if model.history_length > 0:
        length = model.history_length
        steps = enc.steps(*[np.asarray(x)[:, -length:] for x in history]).double()
    return obs, act, steps


def _belief(net, obs, act, steps) -> torch.Tensor:
    return net.belief_from_memory(net.memory(steps), obs, act)


def jacobian_projection(model, query_belief: np.ndarray, observations: np.ndarray, actions,
                        history: History | None, nodes: int = NODES) -> dict:
    """SimplEx's Jacobian projection of R corpus rows on one query (module docstring).

    ``query_belief`` (d_b,); the rows' ``observations`` (R, d_o), ``actions`` (R, d_a) or (R,)
    (value mode; ignored in imitation mode), ``history`` an R-row History. Returns float64
    arrays: ``observation`` (R, d_o), ``action`` (R, d_a_in) or None, ``history`` (R, L, F)
    or None (the attributions p^c_i), ``projection`` (R,) p^c, ``completeness_gap`` (R,)."""
    net = _double_net(model)
    obs, act, steps = encoded_inputs(model, observations, actions, history)
    r = obs.shape[0]
    with torch.no_grad():
        zeros = [None if x is None else torch.zeros_like(x[:1]) for x in (obs, act, steps)]
        h0 = _belief(net, *zeros)[0]
        end = _belief(net, obs, act, steps)
    y = torch.as_tensor(np.asarray(query_belief, np.float64))
    shift = y - h0
    u = shift / torch.clamp(shift.dot(shift), min=1e-300)
    t, w = np.polynomial.legendre.leggauss(int(nodes))
    t = torch.as_tensor((t + 1.0) / 2.0)           # nodes on [0, 1]
    w = torch.as_tensor(w / 2.0)                    # weights summing to 1
    n = len(t)

    def path(x):                                    # (R, ...) -> (n * R, ...) on the path
        if x is None:
            return None
        scale = t.repeat_interleave(r).reshape(-1, *([1] * (x.ndim - 1)))
        return (scale * x.repeat(n, *([1] * (x.ndim - 1)))).requires_grad_(True)

    inputs = [path(x) for x in (obs, act, steps)]
    beliefs = _belief(net, *inputs)                 # (n * R, d_b)
    weight = w.repeat_interleave(r)                 # quadrature weight of each path point
    (weight * (beliefs @ u)).sum().backward()
    out = {}
    for name, x, xt in zip(("observation", "action", "history"), (obs, act, steps), inputs):
        if x is None:
            out[name] = None
            continue
        grad = xt.grad.reshape(n, *x.shape).sum(0)  # integral of the gradient, (R, ...)
        out[name] = (x * grad).detach().numpy()
    with torch.no_grad():
        projection = ((end - h0) @ u).numpy()
    total = sum(v.reshape(r, -1).sum(1) for v in out.values() if v is not None)
    out["projection"] = projection
    out["completeness_gap"] = np.abs(total - projection)
    return out


def feature_names(model, corpus) -> dict:
    """Names of the attributed features: ``observation`` (d_o), ``action`` (d_a_in) or None,
    ``history_step`` (F) of one history step (``obs``, ``act``, ``reward``, ``present``)."""
    space = corpus.observation_space or {}
    obs = list(space.get("names") or [f"obs_{i}" for i in range(model.dims["observation"])])
    aspace = corpus.action_space or {}
    n_in = int(model.dims["action_input"])
    act = list(aspace.get("names") or [])
    if model.discrete:  # one-hot: one feature per action (labelled when each has a name)
        act = [f"action={act[i] if len(act) == n_in else i}" for i in range(n_in)]
    elif len(act) != n_in:
        act = [f"act_{i}" for i in range(n_in)]
    # a history step holds the action in every mode; the input action only in value mode
    return {"observation": obs, "action": act if model.mode == "value" else None,
            "history_step": obs + act + ["reward", "present"]}
