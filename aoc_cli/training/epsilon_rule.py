"""The controller's epsilon decided on held-out episodes of the log (continuous actions, value
mode): keep as many of the K uniform candidates as lie as near the corpus as the log's own
actions do.

After training, at up to :data:`ROWS` rows of the validation episodes (the episodes the model
did not fit), the logged action and K uniform candidates in the action box are each
decomposed over the training rows' beliefs (the residual r, as the controller computes it,
with the k rule's k). ``q`` of a row is the share of the candidates nearer the corpus than
the logged action (r(candidate) < r(logged)). The rule:

    epsilon = the median q, rounded up to a tenth, between :data:`LOW` and :data:`HIGH`

(the paper's 0.5 at most): the filter then keeps the candidates at least as near the corpus
as the behaviour's own action at half of the held-out steps. Measured (docs/design.md,
"Settings from the log's evidence"): the maze's experts 0.04 (epsilon 0.1), two-gates 0.04
(0.1), lunar's noisy lander 0.11 (0.2), pendulum-het upright 0.225 (0.3).
"""

from __future__ import annotations

import time

import numpy as np
import torch

from aoc_cli.belief.model import Encoder
from aoc_cli.decompose import decompose, default_k
from aoc_cli.index.search import BeliefIndex
from aoc_cli.training.record import Recording

#: Held-out rows measured, K uniform candidates each.
ROWS, K = 200, 100
#: The range of the epsilon decided.
LOW, HIGH = 0.1, 0.5


def action_box(corpus) -> tuple[np.ndarray, np.ndarray]:
    """(low, high) (d_a,) of the corpus's action box: the space's bounds where finite, else
    the logged actions' range (as the controller samples its candidates)."""
    space = corpus.action_space or {}
    acts = np.asarray(corpus.actions, dtype=np.float64).reshape(corpus.n_rows, -1)
    low = np.asarray(space.get("low", acts.min(0)), dtype=np.float64).reshape(-1)
    high = np.asarray(space.get("high", acts.max(0)), dtype=np.float64).reshape(-1)
    bad = ~(np.isfinite(low) & np.isfinite(high))
    low[bad], high[bad] = acts.min(0)[bad], acts.max(0)[bad]
    return low, high


def rule(q: np.ndarray) -> float:
    """The epsilon of the held-out rows' shares ``q`` (module docstring)."""
    return float(np.clip(np.ceil(np.median(q) * 10 - 1e-9) / 10, LOW, HIGH))


def epsilon_validation(corpus, seed: int = 0):
    """An ``inspect`` hook for :func:`aoc_cli.belief.train.train_model` (value mode,
    continuous actions): returns ``val_epsilon`` (the rule's epsilon), ``val_epsilon_q`` (the
    10/25/50/75/90% quantiles of q) and ``val_epsilon_rows``."""
    low, high = action_box(corpus)
    logged = np.asarray(corpus.actions, dtype=np.float64).reshape(corpus.n_rows, -1)

    def inspect(net, inputs, data, norm) -> dict:
        rng = np.random.default_rng(seed)
        device = inputs.obs.device
        encoder = Encoder(norm, False, None, device)
        tr = torch.as_tensor(data.train_rows, device=device)
        with torch.no_grad():
            b_tr = torch.cat([net(*inputs.batch(tr[i:i + 65536]))[0]
                              for i in range(0, len(tr), 65536)]).cpu().numpy()
            rows = np.sort(rng.choice(data.val_rows, size=min(ROWS, len(data.val_rows)),
                                      replace=False))
            obs, _act, steps = inputs.batch(torch.as_tensor(rows, device=device))
            memory = net.memory(steps)
            actions = np.concatenate([logged[rows][:, None, :],
                                      rng.uniform(low, high, (len(rows), K, len(low)))], 1)
            n = K + 1
            b = net.belief_from_memory(
                None if memory is None else memory.repeat_interleave(n, 0),
                obs.repeat_interleave(n, 0),
                encoder.actions(actions.reshape(len(rows) * n, -1))).cpu().numpy()
        dec = decompose(b_tr, b, k=default_k(b_tr.shape[1]),
                        index=BeliefIndex.build(b_tr, kind="flat"))
        res = np.asarray(dec.residual, dtype=np.float64).reshape(len(rows), n)
        q = np.mean(res[:, 1:] < res[:, :1], axis=1)
        return {"val_epsilon": rule(q),
                "val_epsilon_q": np.quantile(q, [0.1, 0.25, 0.5, 0.75, 0.9]).round(4).tolist(),
                "val_epsilon_rows": int(len(rows))}

    return inspect


def recording_hook(corpus, seed: int, recording: Recording, progress=None):
    """:func:`epsilon_validation`'s hook, also recording its choice in ``recording`` (the
    ``controller`` settings and the ``settings`` reasons that ``aoc train`` saves with the
    model: training merges the record into the metrics after the hook ran). ``progress``
    (:mod:`aoc_cli.progress`): a label while it measures."""
    measure = epsilon_validation(corpus, seed)

    def inspect(net, inputs, data, norm) -> dict:
        started = time.perf_counter()
        if progress is not None:
            progress(0, None, f"deciding epsilon: {ROWS} held-out steps x {K + 1} actions")
        out = measure(net, inputs, data, norm)
        q = out["val_epsilon_q"]
        record = recording.record.with_controller(epsilon=out["val_epsilon"])
        recording.record = record.deciding({
            "setting": "epsilon", "value": out["val_epsilon"],
            "why": f"at {out['val_epsilon_rows']} steps of held-out episodes the logged action "
                   f"is nearer the corpus than {q[2]:.0%} of {K} uniform candidates (median; "
                   f"10-90%: {q[0]:.0%}-{q[4]:.0%}): keep that share, rounded up to a tenth, "
                   f"{LOW:g}-{HIGH:g}",
            "seconds": time.perf_counter() - started})
        return out

    return inspect
