"""Work on Ray: start or join it (:func:`start_ray`) and run tasks with retry and progress
(:func:`as_completed`, :func:`map_chunks`).

Used by ``aoc collect --workers`` (chunks of a corpus), ``aoc evaluate --workers`` (chunks of
held-out episodes) and ``aoc bench --workers`` (experiment cells). Ray is imported only when a
run asks for workers (:func:`start_ray`); the single-machine path never imports it.

* With ``address`` (or ``$RAY_ADDRESS``) a run joins that cluster; otherwise it starts a local
  Ray with ``num_cpus=workers``. Every worker process runs with one OpenMP/BLAS thread and
  passive waits (:data:`WORKER_ENV`), and this process's ``PYTHONPATH``.
* A task whose worker dies is run again by Ray (``max_retries``); a task that raises is
  resubmitted by :func:`as_completed` until its ``attempts`` are used, then reported with
  its error.
"""

from __future__ import annotations

import logging
import os
from collections.abc import Callable, Iterator, Sequence

from aoc_cli.errors import AocError

#: Environment of every worker: one thread per task for the OpenMP/BLAS pools, passive waits.
WORKER_ENV = {"OMP_NUM_THREADS": "1", "MKL_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1",
              "OMP_WAIT_POLICY": "PASSIVE"}


def start_ray(workers: int | None, address: str | None):
    """Join the cluster at ``address`` (or ``$RAY_ADDRESS``), else start a local Ray with
    ``num_cpus=workers``; returns the ray module."""
    try:
        import ray  # optional dependency (the ray extra): imported only when workers are asked
    except ImportError:
        raise AocError("workers needs Ray: pip install -e '.[ray]'", "workers") from None
    address = address or os.environ.get("RAY_ADDRESS") or None
    env = dict(WORKER_ENV)
    if os.environ.get("PYTHONPATH"):
        env["PYTHONPATH"] = os.environ["PYTHONPATH"]
    if not ray.is_initialized():
        options = {"runtime_env": {"env_vars": env}, "log_to_driver": False,
                   "logging_level": logging.ERROR}
        try:
            if address:
                ray.init(address=address, **options)
            else:
                ray.init(num_cpus=int(workers), include_dashboard=False, **options)
        except (ConnectionError, RuntimeError, ValueError) as err:
            raise AocError(f"could not start or join Ray"
                           f"{' at ' + address if address else ''}: {err}") from None
    return ray


def capacity(ray, workers: int | None) -> int:
    """Tasks at once: ``workers``, else the cluster's CPUs."""
    return int(workers) if workers else max(1, int(ray.cluster_resources().get("CPU", 1)))


def as_completed(ray, submit: Callable[[object, int], object], items: Sequence, *,
                 limit: int | None = None, attempts: int = 1
                 ) -> Iterator[tuple[object, int, object, BaseException | None]]:
    """Yield ``(item, attempt, result, error)`` as each task finishes.

    ``submit(item, attempt)`` starts the task (a Ray object ref); at most ``limit`` run at once
    (all when None), started in ``items``' order. A task that raises is yielded with ``result``
    None and its ``error``; while ``attempt < attempts`` it is also submitted again (at the back
    of the queue), so the last yield of an item is its result or its final error."""
    queue = [(item, 1) for item in items]
    running: dict = {}
    while queue or running:
        while queue and (limit is None or len(running) < limit):
            item, attempt = queue.pop(0)
            running[submit(item, attempt)] = (item, attempt)
        finished, _ = ray.wait(list(running), num_returns=1)
        item, attempt = running.pop(finished[0])
        try:
            result = ray.get(finished[0])
        except Exception as err:  # RayTaskError, a dead worker
            if attempt < attempts:  # the caller sees the failure; the item runs again
                queue.append((item, attempt + 1))
            yield item, attempt, None, err
        else:
            yield item, attempt, result, None


def map_chunks(fn: Callable, chunks: Sequence[tuple], *, workers: int | None = None,
               address: str | None = None, retries: int = 1,
               done: Callable[[int, object], None] | None = None) -> list:
    """``[fn(*chunk) for chunk in chunks]``, each call a Ray task (``num_cpus=1``); the results
    in ``chunks``' order. A task whose worker dies runs again up to ``retries`` times; an
    exception raised by ``fn`` is raised here. ``done(i, result)`` as chunk ``i`` finishes
    (for progress)."""
    ray = start_ray(workers, address)
    remote = ray.remote(num_cpus=1, max_retries=retries)(fn)
    results: list = [None] * len(chunks)
    for i, _attempt, result, error in as_completed(
            ray, lambda i, _attempt: remote.remote(*chunks[i]), range(len(chunks))):
        if error is not None:
            raise error
        results[i] = result
        if done is not None:
            done(i, result)
    return results


def error_text(err: BaseException) -> str:
    """One line of a failed task's error: the cause's type and last line."""
    cause = getattr(err, "cause", None)
    if cause is not None and not isinstance(cause, type(err)):
        err = cause
    text = str(err).strip().splitlines()
    return f"{type(err).__name__}: {text[-1] if text else ''}"[:300]
