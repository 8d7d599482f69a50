"""Thread control for small, latency-bound work: numpy's BLAS and FAISS's OpenMP.

The decomposition multiplies many tiny matrices. OpenBLAS splits even a (100, 20) x (20, 500)
product over threads, and next to FAISS's OpenMP threads on a small machine that turns a 50 us
product into milliseconds. `single_threaded_blas()` sets OpenBLAS's thread-local thread count
to 1 for the duration of a call (openblas_set_num_threads_local, OpenBLAS >= 0.3.27) and
restores it; where numpy does not ship that OpenBLAS it does nothing. `faiss_threads(n)` does
the same for FAISS's OpenMP threads. Together with torch's threads they make the process-wide
context of :mod:`aoc_cli.threads`; this module is the part of it that needs no torch.
"""

from __future__ import annotations

import ctypes
import glob
import os
from contextlib import contextmanager

import faiss
import numpy as np

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
    lot to their synchronisation (measured: 30 ms with 2 threads against 2.4 ms with 1 for one
    query against 100k rows).
    """
    if n <= 0:
        yield
        return
    previous = faiss.omp_get_max_threads()
    if previous != n:
        faiss.omp_set_num_threads(n)
    try:
        yield
    finally:
        if previous != n:
            faiss.omp_set_num_threads(previous)
