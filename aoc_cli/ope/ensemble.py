"""Many fitted Q evaluations trained at once in plain torch: an ensemble of small Q networks
that share one log, their weights stacked along a leading dimension.

Why: one update of a small network (icu-sepsis's: 48 -> 64 -> 64 -> 25) is nearly all
per-call overhead (Python, autograd, Adam's dispatch), not arithmetic, and
:func:`aoc_cli.ope.fqe.fqe_policies` runs a fit and its refits per policy, several policies
an ``aoc evaluate``: tens of thousands of updates. Stacking the members' weights (``torch.
baddbmm``) costs one update's overhead for all of them (docs/notes/benchmarks-rounds.md, "FQE as one
batched ensemble").

Each member is fitted Q evaluation as d3rlpy's DiscreteFQE runs it (the reference of
tests/ope/test_ope_ensemble.py): linear layers with a ReLU after each but the last, torch's
default initialisation; an update regresses Q(s_t, a_t) on y_t = r_t + gamma
Q_target(s_{t+1}, a') (1 - terminal_t), a' the evaluated policy's action at the next logged
step, by the Huber loss's mean over the member's mini-batch, one step of
``torch.optim.Adam(fused=True)`` (autograd's gradient; Adam is elementwise, and the loss a
sum of the members' own means, so stacked members do not interact); the target network is
synced after the step when the member's step count (before it rises) is a multiple of the
interval. Each member draws its mini-batch and next actions from its own pool and policy
(:func:`sampler`).

Censored steps (the last of an episode cut short, :func:`aoc_cli.ope.fqe.fqe_policies`'s
``truncated``): the episode went on to a state the log does not hold, so that step's target
bootstraps from the value of its next state as the continuing transitions predict it: the
network has a second head C(s, a) regressed, on the transitions that continue in the log, on
the target's value of their next state; a censored step's target is r_t + gamma
C_target(s_t, a_t) (``fit.cut`` marks them; without any, the network has no second head).

Shapes: M members; layer l's weights (M, d_in, d_out), biases (M, 1, d_out); a mini-batch
(M, B, d_o) of observations; Q (M, B, n).
"""

from __future__ import annotations

import numpy as np


class FQEEnsemble:
    """M members on the log of ``fit`` (an :class:`aoc_cli.ope.fqe.FQEFit`: its standardised
    observations, actions, rewards, next rows, terminals and censored steps, mini-batch size,
    gamma, target interval, learning rate), each starting from the weights ``initial`` (torch's
    layout: [W_1 (out, in), b_1 (out,), ...]; None: ``fit.initial()``), fresh Adam, step count
    0. :meth:`train` takes what each member evaluates and where it draws its rows."""

    def __init__(self, fit, M: int, initial: list | None = None):
        import torch

        layers = fit.initial() if initial is None else [torch.as_tensor(t) for t in initial]
        self.fit, self.M = fit, int(M)
        self.counts = np.zeros(self.M, np.int64)
        self.params = [_stacked(t, self.M).requires_grad_(True) for t in layers]
        self.target = [p.detach().clone() for p in self.params]
        self.optim = torch.optim.Adam(self.params, lr=fit.learning_rate, fused=True)
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
        out.optim = torch.optim.Adam(out.params, **self.optim.defaults)
        for p, q in zip(self.params, out.params):
            if p in self.optim.state:
                out.optim.state[q] = {k: (v.clone() if k == "step" else rep(v))
                                      for k, v in self.optim.state[p].items()}
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
                    theirs = part.optim.state[q]
                    mine = self.optim.state.setdefault(
                        p, {k: torch.zeros_like(p) for k in theirs if k != "step"})
                    mine["step"] = theirs["step"].clone()
                    for key in ("exp_avg", "exp_avg_sq"):
                        mine[key][at] = theirs[key]
        self.counts[np.asarray(members, np.int64)] = part.counts

    def _forward(self, layers: list, x):
        """(M, B, outputs) for observations x (M, B, d_o): linear layers with a ReLU after each
        but the last (the outputs: Q of every action, then C's with censored steps)."""
        import torch

        pairs = list(zip(layers[0::2], layers[1::2]))
        h = x
        for i, (w, b) in enumerate(pairs):
            h = torch.baddbmm(b, h, w)
            if i < len(pairs) - 1:      # in place: baddbmm's backward needs its inputs, not
                h = torch.relu_(h)      # its output, and ReLU's needs its output (3-5% a step)
        return h

    def train(self, steps: int, cums: np.ndarray, policy_of: np.ndarray, pools: list,
              rng: np.random.Generator, draw=None, progress=None,
              schedule: str = "constant") -> None:
        """``steps`` updates of every member (module docstring). Member m evaluates the
        policy of cumulative probabilities ``cums[policy_of[m]]`` ((P, N, n) in all) and draws
        its B rows uniformly from ``pools[m]`` (a multiset of row indices; None: every row),
        with ``rng``. ``draw()`` -> (rows (M, B), next actions (M, B)) replaces that draw.
        ``progress(done)`` every 100 steps. ``schedule`` "constant" or "cosine": the learning
        rate annealed from its value to 0 over these ``steps`` (as torch's CosineAnnealingLR),
        so that the last weights are not one noisy step."""
        import torch
        import torch.nn.functional as F

        fit, B, M = self.fit, self.fit.batch, self.M
        if schedule not in ("constant", "cosine"):
            raise ValueError(f"unknown learning rate schedule {schedule!r}")
        if draw is None:
            draw = sampler(fit, cums, np.asarray(policy_of, np.int64), pools, rng, M)
        alive = (1.0 - fit.last).astype(np.float32)                          # (N,)
        discount = (fit.gamma * alive).astype(np.float32)                    # (N,)
        cut = fit.cut.astype(np.float32) if fit.cut.any() else None          # (N,) censored
        table = self._next_table()
        next_of = None if table is None else table.of[fit.nxt]     # (N,) next's distinct row
        members = np.arange(M)[:, None]
        act = torch.from_numpy(fit.act)
        seed = torch.tensor(1.0 / B)        # backward of the sum / B: each member's mean
        group = self.optim.param_groups[0]
        lr0 = group["lr"]
        for step in range(int(steps)):
            if schedule == "cosine":
                group["lr"] = lr0 * 0.5 * (1.0 + np.cos(np.pi * step / int(steps)))
            idx, a_next = draw()                                             # (M, B) each
            if table is None:               # (numpy gathers: cheaper than torch's indexing)
                with torch.no_grad():
                    q_next = self._forward(self.target, torch.from_numpy(fit.x[fit.nxt[idx]]))
                    v_next = q_next.gather(2, torch.from_numpy(a_next)[..., None])[..., 0]
                y = torch.from_numpy(fit.rew[idx]) + torch.from_numpy(discount[idx]) * v_next
            else:
                v_next = table.q[members, next_of[idx], a_next]
                y = torch.from_numpy(fit.rew[idx] + discount[idx] * v_next)  # (M, B)
                v_next = torch.from_numpy(v_next)
            rows = torch.from_numpy(idx).view(-1)
            a = act.index_select(0, rows).view(M, B, 1)
            if cut is not None:             # a censored step's target: r + gamma C_target
                y = y + torch.from_numpy(cut[idx]) * (fit.gamma * self._continued(idx, a))
            out = self._forward(self.params, self.x.index_select(0, rows).view(M, B, -1))
            # the sum over members of each member's mean Huber loss over its mini-batch
            loss = F.huber_loss(out.gather(2, a)[..., 0], y, reduction="sum")
            if cut is not None:             # C on the next state's value where it continues
                go = torch.from_numpy(alive[idx] * (1.0 - cut[idx]))
                c = out.gather(2, a + fit.n_actions)[..., 0]
                loss = loss + (F.huber_loss(c, v_next, reduction="none") * go).sum()
            for p in self.params:           # Adam's zero_grad(set_to_none), without its hooks
                p.grad = None
            loss.backward(seed)
            self.optim.step()
            sync = self.counts % fit.interval == 0
            if sync.any():                  # after the step, as d3rlpy's DiscreteFQE
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

    def _continued(self, idx, a):
        """(M, B) C_target(s_t, a_t) of the drawn rows ``idx`` and their logged actions ``a``
        (M, B, 1): the target network's value of the state after a step that went on."""
        import torch

        with torch.no_grad():
            x = torch.from_numpy(self.fit.x[idx])
            return self._forward(self.target, x).gather(2, a + self.fit.n_actions)[..., 0]

    def _next_table(self) -> _TargetTable | None:
        """The target network's Q of every distinct next observation, when computing it at
        each sync costs less than the target's forward pass over every mini-batch until the
        next sync (distinct observations at most ``interval`` x B: a log whose states repeat,
        e.g. icu-sepsis's 713 in 45,000 rows); None otherwise. The same values as the
        per-batch forward pass (each row's Q is its own product), a quarter of an update's
        arithmetic less."""
        xu, of = self.fit.distinct()
        if len(xu) > self.fit.interval * self.fit.batch:
            return None
        table = _TargetTable(xu, of)
        table.refresh(self)
        return table

    def q(self, rows: np.ndarray | None = None, block: int = 8192) -> np.ndarray:
        """(M, len(rows), n) every member's Q_hat of the given rows (None: every row) and
        every action."""
        import torch

        rows = np.arange(self.fit.n_rows) if rows is None else np.asarray(rows, np.int64)
        n = self.fit.n_actions
        out = np.empty((self.M, len(rows), n))
        with torch.no_grad():
            for lo in range(0, len(rows), block):
                x = self.x[torch.from_numpy(rows[lo:lo + block])]
                out[:, lo:lo + len(x)] = self._forward(
                    self.params, x.expand(self.M, -1, -1))[..., :n].double().numpy()
        return out


class _TargetTable:
    """Q of the target network at each distinct observation ``xu`` (U, d_o), every member:
    ``q`` (M, U, outputs); ``of`` (N,) the distinct observation of each row."""

    def __init__(self, xu: np.ndarray, of: np.ndarray):
        import torch

        self.xu, self.of = torch.from_numpy(np.ascontiguousarray(xu)), of
        self.q = None

    def refresh(self, ens: FQEEnsemble) -> None:
        import torch

        with torch.no_grad():
            self.q = ens._forward(ens.target, self.xu.expand(ens.M, -1, -1)).numpy()


def sampler(fit, cums: np.ndarray, policy_of: np.ndarray, pools: list, rng, M: int,
            keep=None):
    """draw() -> (rows (M, B), next actions (M, B)): member m's B rows uniform over its pool,
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

    def draw():
        u_rows, u = rng.random((2, M, B))[:, keep]          # the rows', then the actions'
        u = u[..., None]
        rows = flat[offsets + (u_rows * lens).astype(np.int64)]             # (K, B)
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


def _stacked(t, M: int):
    """One layer's torch-layout parameter, weight (out, in) or bias (out,), as M stacked
    copies in the batched layout: (M, in, out) or (M, 1, out)."""
    t = t.detach().float()
    one = t.t() if t.ndim == 2 else t[None, :]
    return one[None].repeat(M, 1, 1).contiguous()
