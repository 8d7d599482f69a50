"""The thread pools of one process, set together and given back: torch's intra-op threads,
FAISS's OpenMP threads and numpy's OpenBLAS threads.

Library code never changes them for good. Work with a thread need of its own runs inside
:func:`thread_limits`, which restores the caller's settings when the block ends:

* a control step (``Controller.decide`` / ``Controller.decompose_candidates``) and the batched scoring of
  ``aoc evaluate`` run in :func:`one_thread`: a step is ~100 small queries, threads only add
  synchronisation there, and torch's and FAISS's pools must not fight over the cores;
* training runs with ``BeliefConfig.threads`` threads in every pool, all of it: the FQE over
  rule 7's sets and its FAISS searches too (default: every core);
* the decomposition keeps BLAS to one thread and a single-query FAISS search to one thread
  (:func:`single_threaded_blas`, :func:`faiss_threads`).

OpenBLAS: the decomposition multiplies many tiny matrices. OpenBLAS splits even a
(100, 20) x (20, 500) product over threads, and next to FAISS's OpenMP threads on a small
machine that turns a 50 us product into milliseconds. :func:`blas_threads` sets OpenBLAS's
thread-local thread count (openblas_set_num_threads_local, OpenBLAS >= 0.3.27) for a block and
restores it; where numpy does not ship that OpenBLAS it does nothing.

A setting already in place costs nothing to set again, so the contexts nest freely.

``OMP_WAIT_POLICY`` is not a setting of a running pool: OpenMP reads it once, when its runtime
is loaded (the first import of torch or FAISS). The ``aoc`` command sets it to ``PASSIVE``
(unless the user set it) in its entry point, before anything loads OpenMP
(:func:`wait_passively`, called by :mod:`aoc_cli.cli.app`); the benchmarks call it first too.
A program using the library decides for itself. Why the command sets it: OpenMP threads
busy-wait by default, and two torch threads training on two cores shared with other processes
ran ~30x slower; a control step, one thread in each pool, does not depend on it
(docs/notes/benchmarks-rounds.md, "One thread context").
"""

from __future__ import annotations

import ctypes
import glob
import os
import sys
from contextlib import ExitStack, contextmanager
from typing import Iterator

import numpy as np


def cores() -> int:
    """The CPU cores this process may run on (its affinity; the CPU count elsewhere)."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # pragma: no cover - not Linux
        return max(1, os.cpu_count() or 1)


def wait_passively() -> bool:
    """Set ``OMP_WAIT_POLICY=PASSIVE`` unless the environment sets it. True when it can still
    take effect (neither torch nor FAISS is loaded yet)."""
    os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")
    return "torch" not in sys.modules and "faiss" not in sys.modules


@contextmanager
def thread_limits(torch: int | None = None, faiss: int | None = None,
                  blas: int | None = None) -> Iterator[None]:
    """Run the block with torch's intra-op threads, FAISS's OpenMP threads and numpy's OpenBLAS
    threads (this thread's) set to the given counts; None (or 0) leaves that pool as it is.
    Each pool is given back its previous count when the block ends."""
    with ExitStack() as stack:
        if torch:
            stack.enter_context(_torch_threads(int(torch)))
        if faiss:
            stack.enter_context(faiss_threads(int(faiss)))
        if blas:
            stack.enter_context(blas_threads(int(blas)))
        yield


def one_thread():
    """:func:`thread_limits` with one thread in every pool: how a control step runs."""
    return thread_limits(torch=1, faiss=1, blas=1)


@contextmanager
def _torch_threads(n: int) -> Iterator[None]:
    import torch  # torch edge: the library's numpy + FAISS layers never load torch

    previous = torch.get_num_threads()
    if previous != n:
        torch.set_num_threads(n)
    try:
        yield
    finally:
        if torch.get_num_threads() != previous:
            torch.set_num_threads(previous)


_SETTER = None
_LOADED = False


def _setter():
    global _SETTER, _LOADED
    if _LOADED:
        return _SETTER
    _LOADED = True
    libs = os.path.join(os.path.dirname(os.path.dirname(np.__file__)), "numpy.libs")
    for path in sorted(glob.glob(os.path.join(libs, "*openblas*.so*"))):
        try:
            lib = ctypes.CDLL(path)
            fn = lib.openblas_set_num_threads_local
        except (OSError, AttributeError):
            continue
        fn.argtypes = [ctypes.c_int]
        fn.restype = ctypes.c_int
        _SETTER = fn
        break
    return _SETTER


@contextmanager
def blas_threads(n: int):
    """Run the block with numpy's OpenBLAS limited to n threads (on this thread only)."""
    fn = _setter()
    if fn is None:
        yield
        return
    previous = fn(int(n))
    try:
        yield
    finally:
        fn(previous)


def single_threaded_blas():
    """Run the block with numpy's OpenBLAS limited to one thread (on this thread only)."""
    return blas_threads(1)


@contextmanager
def faiss_threads(n: int):
    """FAISS's OpenMP thread count set to n (0: unchanged) for the block, then restored.

    A single-query search gains nothing from threads and, on a busy 2-core machine, loses a
    lot to their synchronisation (docs/notes/benchmarks-rounds.md, "Figures once in docstrings").
    """
    if n <= 0:
        yield
        return
    import faiss  # FAISS edge: importing this module must not load OpenMP (wait_passively)

    previous = faiss.omp_get_max_threads()
    if previous != n:
        faiss.omp_set_num_threads(n)
    try:
        yield
    finally:
        if previous != n:
            faiss.omp_set_num_threads(previous)
