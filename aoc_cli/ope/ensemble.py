"""Many fitted Q evaluations trained at once: d3rlpy's DiscreteFQE update, batched over an
ensemble of members that share one log.

Why: one DiscreteFQE update of a small network (icu-sepsis's: 48 -> 64 -> 64 -> 25) is
nearly all per-call overhead (Python, autograd, Adam's per-tensor loop), not arithmetic, and
:func:`aoc_cli.ope.fqe.bootstrap_fqe` runs a fit and its refits per policy, several policies
an ``aoc evaluate``: tens of thousands of updates. Stacking the members' weights along a
leading dimension (``torch.bmm``) costs one update's overhead for all of them (the figures:
docs/benchmarks.md, "FQE as one batched ensemble").

Each member is d3rlpy's DiscreteFQE, not a re-design of it: its network is the one d3rlpy
built and initialised (:class:`aoc_cli.ope.fqe.FQEFit`: a ``VectorEncoder`` of ReLU
layers, then a linear head), read from and written back to the d3rlpy modules (weights,
target weights, Adam's moments, the step count); an update is DiscreteFQEImpl.inner_update's:
Huber loss of Q(s_t, a_t) against r_t + gamma Q_target(s_{t+1}, a') (1 - terminal_t), the
mean over the mini-batch, one torch Adam step with d3rlpy's settings (Adam is elementwise, so
stacked members do not interact), then the target network synced when the member's step count
(before it rises) is a multiple of the interval, as d3rlpy does. Each member draws its
mini-batch and next actions from its own generator exactly as ``FQEFit.train`` does, so a
member started from a fit's state reproduces that fit's d3rlpy training to float rounding
(tests/ope/test_ope_ensemble.py checks it against d3rlpy's own update).

Shapes: M members; layer l's weights (M, d_in, d_out), biases (M, 1, d_out); a mini-batch
(M, B, d_o) of observations; Q (M, B, n).
"""

from __future__ import annotations

import numpy as np


class FQEEnsemble:
    """M members on the log of ``fit`` (an :class:`aoc_cli.ope.fqe.FQEFit`: its
    standardised observations, actions, rewards, next rows, terminals, mini-batch size, gamma,
    target interval and Adam settings). Member m starts from ``states[m]`` (an
    ``FQEFit.snapshot()``) at step count ``counts[m]`` (the d3rlpy model's ``_grad_step``).
    :meth:`train` takes what each member evaluates and where it draws its rows."""

    def __init__(self, fit, states: list, counts: list):
        import torch

        self.fit, self.M = fit, len(states)
        self.counts = np.asarray(counts, np.int64)
        keys = list(states[0]["q"])
        self.keys = keys
        self.is_bias = [k.endswith("bias") for k in keys]
        if self.is_bias != [False, True] * (len(keys) // 2) or not all(
                k.endswith("weight") for k, b in zip(keys, self.is_bias) if not b):
            raise ValueError(f"not a stack of linear layers: {keys}")
        stack = lambda sd: [torch.stack([s[k] for s in sd]).detach().clone() for k in keys]
        self.params = [_bmm(p, b).requires_grad_(True)
                       for p, b in zip(stack([s["q"] for s in states]), self.is_bias)]
        self.target = [_bmm(p, b) for p, b in zip(stack([s["target"] for s in states]),
                                                  self.is_bias)]
        group = fit.fqe.impl.modules.optim.optim.param_groups[0]
        # foreach: the per-tensor loop's updates in one call (the same values)
        self.optim = torch.optim.Adam(self.params, lr=group["lr"], betas=group["betas"],
                                      eps=group["eps"], weight_decay=group["weight_decay"],
                                      amsgrad=group["amsgrad"], foreach=True)
        moments = [s["optim"]["optim"]["state"] for s in states]
        if all(len(m) for m in moments):
            if len({float(m[0]["step"]) for m in moments}) != 1:
                raise ValueError("an ensemble's members must share Adam's step count")
            for i, (p, b) in enumerate(zip(self.params, self.is_bias)):
                self.optim.state[p] = {"step": moments[0][i]["step"].clone(), **{
                    key: _bmm(torch.stack([m[i][key] for m in moments]), b)
                    for key in ("exp_avg", "exp_avg_sq")}}
        elif any(len(m) for m in moments):
            raise ValueError("an ensemble's members must all be fresh or all trained")
        self.gamma = float(fit.fqe.config.gamma)
        self.interval = int(fit.fqe.config.target_update_interval)
        self.x = torch.from_numpy(fit.x)                                     # (N, d_o)

    def repeat(self, r: int, members=None) -> FQEEnsemble:
        """A new ensemble of len(members) * r members, each of ``members`` (None: all M) here r
        times in a row (weights, target, Adam's moments, step count): the warm starts of r
        refits per member."""
        import copy

        import torch

        keep = torch.arange(self.M) if members is None else torch.as_tensor(
            np.asarray(members, np.int64))
        out = copy.copy(self)
        out.M = len(keep) * r
        out.counts = np.repeat(self.counts[keep.numpy()], r)
        rep = lambda t: t.detach()[keep].repeat_interleave(r, dim=0).clone()
        out.params = [rep(p).requires_grad_(True) for p in self.params]
        out.target = [rep(t) for t in self.target]
        old = self.optim
        out.optim = type(old)(out.params, **{k: v for k, v in old.defaults.items()})
        for p, q in zip(self.params, out.params):
            if p in old.state:
                out.optim.state[q] = {"step": old.state[p]["step"].clone(),
                                      **{k: rep(old.state[p][k])
                                         for k in ("exp_avg", "exp_avg_sq")}}
        return out

    def put(self, members, part: FQEEnsemble) -> None:
        """Write ``part``'s members (a :meth:`repeat` ``(1, members)`` of this ensemble,
        trained since) back at ``members``: weights, target, Adam's moments and step count
        (a part trains every step, as the whole would), step counts."""
        import torch

        at = torch.as_tensor(np.asarray(members, np.int64))
        with torch.no_grad():
            for mine, theirs in ((self.params, part.params), (self.target, part.target)):
                for p, q in zip(mine, theirs):
                    p[at] = q
            for p, q in zip(self.params, part.params):
                if q in part.optim.state:
                    if p not in self.optim.state:
                        self.optim.state[p] = {k: (v.clone() if k == "step" else
                                                   torch.zeros_like(p))
                                               for k, v in part.optim.state[q].items()}
                    mine, theirs = self.optim.state[p], part.optim.state[q]
                    mine["step"] = theirs["step"].clone()
                    for key in ("exp_avg", "exp_avg_sq"):
                        mine[key][at] = theirs[key]
        self.counts[np.asarray(members, np.int64)] = part.counts

    def _forward(self, layers: list, x):
        """(M, B, n) Q of every action for observations x (M, B, d_o): linear layers with a
        ReLU after each but the last (d3rlpy's VectorEncoder, then its linear head)."""
        import torch

        pairs = list(zip(layers[0::2], layers[1::2]))
        h = x
        for i, (w, b) in enumerate(pairs):
            h = torch.baddbmm(b, h, w)
            if i < len(pairs) - 1:
                h = torch.relu(h)
        return h

    def train(self, steps: int, cums: np.ndarray, policy_of: np.ndarray, pools: list,
              rng: np.random.Generator, draw=None, progress=None,
              schedule: str = "constant") -> None:
        """``steps`` updates of every member (module docstring). Member m evaluates the
        policy of cumulative probabilities ``cums[policy_of[m]]`` ((P, N, n) in all) and draws
        its B rows uniformly from ``pools[m]`` (a multiset of row indices; None: every row),
        with ``rng``. ``draw()`` -> (rows (M, B), next actions (M, B)) replaces that draw
        (the tests replay d3rlpy's). ``progress(done)`` every 100 steps. ``schedule``
        "constant" (d3rlpy's default) or "cosine": the learning rate annealed from its value to
        0 over these ``steps`` (torch's CosineAnnealingLR, which d3rlpy's
        CosineAnnealingLRFactory makes), so that the last weights are not one noisy step."""
        import torch

        fit, B = self.fit, self.fit.batch
        if draw is None:
            draw = sampler(fit, cums, np.asarray(policy_of, np.int64), pools, rng, self.M)
        alive = 1.0 - fit.last.astype(np.float32)                            # (N,)
        table = self._next_table()
        members = np.arange(self.M)[:, None]
        act = torch.from_numpy(fit.act)
        group = self.optim.param_groups[0]
        lr0 = group["lr"]
        if schedule not in ("constant", "cosine"):
            raise ValueError(f"unknown learning rate schedule {schedule!r}")
        for step in range(int(steps)):
            if schedule == "cosine":
                group["lr"] = lr0 * 0.5 * (1.0 + np.cos(np.pi * step / int(steps)))
            idx, a_next = draw()                                             # (M, B) each
            with torch.no_grad():           # (numpy gathers: cheaper than torch's indexing)
                if table is None:
                    q_next = self._forward(self.target, torch.from_numpy(fit.x[fit.nxt[idx]]))
                    q_next = q_next.gather(2, torch.from_numpy(a_next)[..., None])[..., 0]
                else:
                    q_next = torch.from_numpy(table.q[members, table.of[fit.nxt[idx]], a_next])
                y = torch.from_numpy(fit.rew[idx]) + self.gamma * q_next * torch.from_numpy(
                    alive[idx])                                              # (M, B)
                rows = torch.from_numpy(idx).view(-1)
                grads = self._grads(self.x.index_select(0, rows).view(self.M, B, -1),
                                    act.index_select(0, rows).view(self.M, B), y)
            self._adam(grads)
            sync = self.counts % self.interval == 0
            if sync.any():                  # after the step, as DiscreteFQEImpl.inner_update
                keep = torch.from_numpy(sync)
                with torch.no_grad():
                    for t, p in zip(self.target, self.params):
                        t[keep] = p[keep]
                if table is not None:
                    table.refresh(self)
            self.counts += 1
            if progress is not None and (step + 1) % 100 == 0:
                progress(step + 1)
        group["lr"] = lr0

    def _grads(self, x, act, y) -> list:
        """The gradient of every member's loss (d3rlpy's: the mean over its mini-batch of the
        Huber loss of Q(s_t, a_t) against ``y``) for each parameter, in ``self.params``'s
        order: observations x (M, B, d_o), logged actions ``act`` (M, B), targets y (M, B).

        Backpropagation written out, the products autograd's would run (a linear layer's
        weight gradient h_in^T dz and input gradient dz W^T, the bias's the sum over the
        batch; a ReLU's the upstream gradient where its output is positive), without its graph
        and engine: ~30% of a small ensemble's update. Huber's derivative is the error clipped
        to [-1, 1]; divided by B (the mean) and put at the logged action of each row.
        tests/ope/test_ope_ensemble.py checks it against autograd's."""
        import torch

        pairs = list(zip(self.params[0::2], self.params[1::2]))
        h, inputs = x, []
        for i, (w, b) in enumerate(pairs):
            inputs.append(h)
            h = torch.baddbmm(b, h, w)
            if i < len(pairs) - 1:
                h = torch.relu_(h)
        at = act[..., None]                                                  # (M, B, 1)
        g = (h.gather(2, at)[..., 0] - y).clamp_(-1.0, 1.0).div_(x.shape[1])  # (M, B)
        dz = torch.zeros_like(h).scatter_(2, at, g[..., None])               # (M, B, n)
        grads = []
        for i in reversed(range(len(pairs))):
            h_in = inputs[i]
            grads += [dz.sum(1, keepdim=True), torch.bmm(h_in.transpose(1, 2), dz)]
            if i:                           # ReLU's output h_in >= 0: sign is its mask
                dz = torch.bmm(dz, pairs[i][0].transpose(1, 2)).mul_(torch.sign(h_in))
        return grads[::-1]

    def _adam(self, grads) -> None:
        """One step of torch's Adam (``self.optim``'s settings and state) with ``grads``:
        the operations of torch.optim.Adam's multi-tensor path (foreach, no weight decay, no
        amsgrad), in its order, without its per-call dispatch (a quarter of a small
        ensemble's update; tests/ope/test_ope_ensemble.py checks it against d3rlpy's)."""
        import torch

        group, state = self.optim.param_groups[0], self.optim.state
        if group["weight_decay"] or group["amsgrad"] or group["maximize"]:
            for p, g in zip(self.params, grads):
                p.grad = g
            self.optim.step()
            return
        if self.params[0] not in state:             # as torch's Adam starts a parameter
            for p in self.params:
                state[p] = {"step": torch.tensor(0.0, dtype=torch.float32),
                            "exp_avg": torch.zeros_like(p, memory_format=torch.preserve_format),
                            "exp_avg_sq": torch.zeros_like(
                                p, memory_format=torch.preserve_format)}
        rec = [state[p] for p in self.params]
        steps = [r["step"] for r in rec]
        avg, avg_sq = [r["exp_avg"] for r in rec], [r["exp_avg_sq"] for r in rec]
        beta1, beta2 = group["betas"]
        with torch.no_grad():
            torch._foreach_add_(steps, torch.tensor(1.0), alpha=1.0)
            torch._foreach_lerp_(avg, list(grads), 1 - beta1)
            torch._foreach_mul_(avg_sq, beta2)
            torch._foreach_addcmul_(avg_sq, list(grads), list(grads), 1 - beta2)
            t = steps[0].item()
            denom = torch._foreach_sqrt(avg_sq)
            torch._foreach_div_(denom, [(1 - beta2 ** t) ** 0.5] * len(denom))
            torch._foreach_add_(denom, group["eps"])
            torch._foreach_addcdiv_(self.params, avg, denom,
                                    [(group["lr"] / (1 - beta1 ** t)) * -1] * len(denom))

    def _next_table(self) -> _TargetTable | None:
        """The target network's Q of every distinct next observation, when computing it at
        each sync costs less than the target's forward pass over every mini-batch until the
        next sync (distinct observations at most ``interval`` x B: a log whose states repeat,
        e.g. icu-sepsis's 713 in 45,000 rows); None otherwise. The same values as the
        per-batch forward pass (each row's Q is its own product), a quarter of an update's
        arithmetic less."""
        xu, of = self.fit.distinct()
        if len(xu) > self.interval * self.fit.batch:
            return None
        table = _TargetTable(xu, of)
        table.refresh(self)
        return table

    def state(self, m: int) -> dict:
        """Member m as an ``FQEFit.snapshot()`` (for ``FQEFit.restore``), with its step
        count under ``count``."""
        import copy

        opt = copy.deepcopy(self.fit.fqe.impl.modules.optim.state_dict())
        opt["optim"]["state"] = {
            i: {"step": self.optim.state[p]["step"].clone(),
                **{key: _unbmm(self.optim.state[p][key], m, b)
                   for key in ("exp_avg", "exp_avg_sq")}}
            for i, (p, b) in enumerate(zip(self.params, self.is_bias)) if p in self.optim.state}
        return {"q": {k: _unbmm(p, m, b) for k, p, b in zip(self.keys, self.params, self.is_bias)},
                "target": {k: _unbmm(p, m, b)
                           for k, p, b in zip(self.keys, self.target, self.is_bias)},
                "optim": opt, "count": int(self.counts[m])}

    def q(self, rows: np.ndarray | None = None, block: int = 8192) -> np.ndarray:
        """(M, len(rows), n) every member's Q_hat of the given rows (None: every row) and
        every action."""
        import torch

        rows = np.arange(self.fit.n_rows) if rows is None else np.asarray(rows, np.int64)
        out = np.empty((self.M, len(rows), self.fit.n_actions))
        with torch.no_grad():
            for lo in range(0, len(rows), block):
                x = self.x[torch.from_numpy(rows[lo:lo + block])]
                out[:, lo:lo + len(x)] = self._forward(
                    self.params, x.expand(self.M, -1, -1)).double().numpy()
        return out


class _TargetTable:
    """Q of the target network at each distinct observation ``xu`` (U, d_o), every member:
    ``q`` (M, U, n); ``of`` (N,) the distinct observation of each row."""

    def __init__(self, xu: np.ndarray, of: np.ndarray):
        import torch

        self.xu, self.of = torch.from_numpy(np.ascontiguousarray(xu)), of
        self.q = None

    def refresh(self, ens: FQEEnsemble) -> None:
        import torch

        with torch.no_grad():
            self.q = ens._forward(ens.target, self.xu.expand(ens.M, -1, -1)).numpy()


def sampler(fit, cums: np.ndarray, policy_of: np.ndarray, pools: list, rng, M: int,
            keep=None, weights: np.ndarray | None = None):
    """draw() -> (rows (M, B), next actions (M, B)): member m's B rows uniform over its pool
    (or, with ``weights`` (N,) >= 0, each entry of the pool drawn in proportion to its row's
    weight: the inverse of its chance to have been kept, :func:`aoc_cli.ope.fqe.fqe_policies`),
    the next action of each drawn from member m's policy at the row's next logged step.
    ``keep`` (member indices, None: all): the draw of those members only, ``(len(keep), B)``
    each, the generator still drawn for all M (the kept members' rows and actions are those
    of the whole draw: a part of the ensemble trained apart, :mod:`aoc_cli.ope.parts`)."""
    pools = [np.arange(fit.n_rows) if p is None else np.asarray(p, np.int64) for p in pools]
    if len(pools) != M or len(policy_of) != M:
        raise ValueError(f"{len(pools)} pools and {len(policy_of)} policies for {M} members")
    keep = np.arange(M) if keep is None else np.asarray(keep, np.int64)
    flat = np.concatenate(pools)
    lens = np.array([len(p) for p in pools], np.int64)[keep, None]          # (K, 1)
    offsets = np.concatenate([[0], np.cumsum([len(p) for p in pools])[:-1]])[keep, None]
    pol = np.asarray(policy_of)[keep, None]
    B, n = fit.batch, fit.n_actions
    # a deterministic policy's cumulative row is 0 before its action and 1 from it on, so the
    # count of entries below u in [0, 1) is that action (0 where u is 0): the same draw with
    # no (M, B, n) gather, where every policy is deterministic (aoc evaluate's decisions)
    chosen = _deterministic(cums)                                           # (P, N) or None
    if weights is not None:     # inverse CDF over the pools' weights, end to end
        cum = np.cumsum(np.asarray(weights, np.float64)[flat])
        ends = offsets + lens - 1                                           # (K, 1)
        first = np.where(offsets > 0, cum[np.maximum(offsets - 1, 0)], 0.0)
        total = cum[ends] - first

    def draw():
        u_rows, u = rng.random((M, B))[keep], rng.random((M, B, 1))[keep]
        if weights is None:
            rows = flat[offsets + (u_rows * lens).astype(np.int64)]         # (K, B)
        else:
            at = np.searchsorted(cum, first + u_rows * total, side="right")
            rows = flat[np.minimum(at, ends)]
        if chosen is not None:
            return rows, np.where(u[..., 0] > 0, chosen[pol, fit.nxt[rows]], 0)
        nxt_a = (cums[pol, fit.nxt[rows]] < u).sum(2).clip(0, n - 1)         # (K, B)
        return rows, nxt_a

    return draw


def joined(*draws):
    """draw() of an ensemble whose members are drawn in groups, each group by its own draw()
    (its own generator: a group's draws do not depend on the others'), stacked in order."""
    def draw():
        parts = [d() for d in draws]
        return (np.concatenate([p[0] for p in parts]), np.concatenate([p[1] for p in parts]))

    return draw


def _deterministic(cums: np.ndarray) -> np.ndarray | None:
    """(P, N) int64 the action of every row of P policies' cumulative probabilities (P, N, n)
    when each row is a step from 0 to 1 (a deterministic policy), else None."""
    cums = np.asarray(cums)
    if cums.ndim != 3 or not np.all((cums == 0.0) | (cums == 1.0)):
        return None
    return (cums == 0.0).sum(2).astype(np.int64)


def _bmm(p, bias: bool):
    """Stacked torch-layout parameters (M, out, in) / (M, out) -> (M, in, out) / (M, 1, out)."""
    return (p[:, None, :] if bias else p.transpose(1, 2)).contiguous().clone()


def _unbmm(p, m: int, bias: bool):
    """Member m of a stacked (M, in, out) weight or (M, 1, out) bias, in torch's layout."""
    return (p[m, 0] if bias else p[m].transpose(0, 1)).detach().clone().contiguous()
