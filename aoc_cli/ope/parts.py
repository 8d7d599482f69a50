"""An FQE ensemble trained in parts on several cores: its members split into contiguous parts,
the first trained in this process, each other in a forked child, then put back together.

Why: a member's update never reads another member's (:mod:`aoc_cli.ope.ensemble`:
stacked weights, each member's own loss, Adam elementwise), so the members divide with no
exchange during training; ``aoc evaluate``'s FQE (a fit of every policy, then 10 refits
each) is most of its time, and one thread gains little on these small products (its
synchronisation costs what the second core adds: docs/notes/benchmarks-rounds.md). Processes, not threads:
the Python between the products holds the GIL (two threads: x1.2 on the fit's few members).

Every part draws its mini-batches exactly as the whole ensemble would: ``make_draw(keep,
rng)`` builds the draw of members ``keep`` from the shared generator ``rng`` (drawn for all
members in every part, :func:`aoc_cli.ope.ensemble.sampler`'s ``keep``), and a fork
starts each child with a copy of that generator in this process's state. So each member
trains on the same rows, next actions and learning rates, in the same floats, whatever the
number of parts (tests/ope/test_ope_parts.py), and this process's generator ends where
one process's would. A child that fails, or has not answered :data:`PATIENCE` times as long
as this process took for its own part (at least :data:`GRACE_SECONDS`) after it, is ended and
its part trained again here from a copy of the generator's starting state: a hung child never
hangs ``aoc evaluate``. Forking needs Linux (elsewhere: one part); each child runs one thread, as
the caller does (the FQE runs under :func:`aoc_cli.threads.one_thread`), and leaves by
``os._exit`` so that nothing of this process (progress bars, temporary files) runs twice.
Results come back as ``.npz`` bytes (``allow_pickle=False``).
"""

from __future__ import annotations

import copy
import io
import multiprocessing
import os
import sys
import time

import numpy as np

from aoc_cli.threads import cores

#: The most parts by default: the fit trains one member per policy (4 in ``aoc evaluate``).
MAX_PARTS = 4
#: How long the children may take beyond this process's own part: PATIENCE times its time,
#: at least GRACE_SECONDS (the parts are the same size; a busy machine slows them unevenly).
PATIENCE = 4.0
GRACE_SECONDS = 60.0


def default_parts() -> int:
    """Parts by default: this process's cores, at most :data:`MAX_PARTS`; 1 where a process
    cannot fork (not Linux)."""
    return min(cores(), MAX_PARTS) if sys.platform.startswith("linux") else 1


def train_parts(ens, steps: int, make_draw, rng: np.random.Generator, parts: int | None = None,
                progress=None, schedule: str = "constant") -> None:
    """``ens.train(steps, ...)`` of every member of ``ens`` in up to ``parts`` parts at once
    (None: :func:`default_parts`; module docstring). ``make_draw(keep, rng)`` -> draw() of the
    members ``keep`` (an int array) from the shared generator ``rng``; ``progress(done)`` as
    :meth:`FQEEnsemble.train`'s, from this process's part (every part takes the same steps)."""
    parts = default_parts() if parts is None else int(parts)
    groups = [g for g in np.array_split(np.arange(ens.M), max(1, min(parts, ens.M))) if len(g)]
    if len(groups) == 1 or not sys.platform.startswith("linux"):
        ens.train(steps, None, None, None, None, draw=make_draw(np.arange(ens.M), rng),
                  progress=progress, schedule=schedule)
        return
    start = copy.deepcopy(rng)          # the generator's state before any part draws
    fork = multiprocessing.get_context("fork")
    children = []
    for keep in groups[1:]:
        part = ens.repeat(1, keep)
        receive, send = fork.Pipe(duplex=False)
        child = fork.Process(target=_child, daemon=True,
                             args=(send, part, steps, make_draw, keep, rng, schedule))
        child.start()
        send.close()
        children.append((keep, part, receive, child))
    try:
        began = time.monotonic()
        mine = ens.repeat(1, groups[0])
        mine.train(steps, None, None, None, None, draw=make_draw(groups[0], rng),
                   progress=progress, schedule=schedule)
        ens.put(groups[0], mine)
        deadline = time.monotonic() + max(GRACE_SECONDS, PATIENCE * (time.monotonic() - began))
        for keep, part, receive, child in children:
            packed = b""
            try:
                if receive.poll(max(0.0, deadline - time.monotonic())):
                    packed = receive.recv_bytes()
            except (EOFError, OSError):
                packed = b""
            if not packed and child.is_alive():       # hung: ended, its part trained here
                child.terminate()
            child.join()
            if packed:
                _unpack(part, packed)
            else:                       # the child died: its part again, here
                part.train(steps, None, None, None, None,
                           draw=make_draw(keep, copy.deepcopy(start)), schedule=schedule)
            ens.put(keep, part)
    finally:
        for _, _, receive, child in children:
            receive.close()
            if child.is_alive():
                child.terminate()
                child.join()


def _child(send, part, steps: int, make_draw, keep, rng, schedule: str) -> None:
    """A forked child: train ``part`` and send its state back (empty bytes on failure)."""
    packed = b""
    try:
        part.train(steps, None, None, None, None, draw=make_draw(keep, rng), schedule=schedule)
        packed = _pack(part)
    except BaseException:   # noqa: BLE001 - on b"" the parent trains this part itself
        pass
    finally:
        try:
            send.send_bytes(packed)
            send.close()
        finally:
            os._exit(0)


def _tensors(part) -> dict:
    """Name -> tensor of everything training changes in ``part``."""
    out = {}
    for i, (p, t) in enumerate(zip(part.params, part.target)):
        out[f"p{i}"], out[f"t{i}"] = p, t
        for key, value in part.optim.state.get(p, {}).items():
            out[f"o{i}_{key}"] = value
    return out


def _pack(part) -> bytes:
    buf = io.BytesIO()
    np.savez(buf, counts=part.counts,
             **{k: v.detach().numpy() for k, v in _tensors(part).items()})
    return buf.getvalue()


def _unpack(part, packed: bytes) -> None:
    """Put a child's trained state (:func:`_pack`) into this process's copy of its part."""
    import torch

    with np.load(io.BytesIO(packed), allow_pickle=False) as z:
        part.counts = z["counts"].copy()
        for i, p in enumerate(part.params):
            if f"o{i}_step" in z and p not in part.optim.state:
                part.optim.state[p] = {}
            for key in ("step", "exp_avg", "exp_avg_sq"):
                if f"o{i}_{key}" in z:
                    part.optim.state[p][key] = torch.from_numpy(z[f"o{i}_{key}"].copy())
        with torch.no_grad():
            for i, (p, t) in enumerate(zip(part.params, part.target)):
                p.copy_(torch.from_numpy(z[f"p{i}"]))
                t.copy_(torch.from_numpy(z[f"t{i}"]))
