"""Bench cells as Ray tasks (``aoc bench EXPERIMENT --workers N [--ray-address ADDR]``).

Imported only when a run asks for workers: the single-machine path never imports Ray.

* Ray: with ``address`` (or ``$RAY_ADDRESS``) the run joins that cluster; otherwise it starts
  a local Ray with ``num_cpus=workers``. At most ``workers`` cells run at once (on a cluster
  without ``workers``: as many as it has CPUs).
* Each group of cells that shares artefacts (their ``prep`` key: a corpus, its models and
  indexes) is prepared by one task first; its cells wait for it. Every task runs with one
  thread for torch, FAISS and BLAS.
* A cell whose task fails (an exception, or its worker died) is run once more; when that fails
  too it becomes one ``failed`` row with the error, so the other cells' results are kept.
* The workers read and write the bench store and the output folder by their paths: on a
  cluster both must be on a filesystem every node mounts at the same path.
"""

from __future__ import annotations

import logging
import os

from aoc_cli.experiments.cells import Cell, CellResult, failed_result, run_cell
from aoc_cli.errors import AocError

#: Environment of every worker: one thread per task for the OpenMP/BLAS pools, passive waits.
WORKER_ENV = {"OMP_NUM_THREADS": "1", "MKL_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1",
              "OMP_WAIT_POLICY": "PASSIVE"}


def start_ray(workers: int | None, address: str | None):
    """Join the cluster at ``address`` (or ``$RAY_ADDRESS``), else start a local Ray with
    ``num_cpus=workers``; returns the ray module."""
    try:
        import ray
    except ImportError:
        raise AocError("--workers needs Ray: pip install -e '.[ray]'") from None
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


def _threads() -> None:
    import faiss
    import torch

    torch.set_num_threads(1)
    faiss.omp_set_num_threads(1)


def worker_context(spec: dict):
    """The Context of a worker: the run's settings, this worker's own artefacts and runner."""
    from aoc_cli.experiments.common import Context
    from aoc_cli.experiments.methods import Budget, Runner
    from aoc_cli.experiments.prepare import Artefacts

    lines: list[str] = []
    runner = _RUNNERS.get(repr(spec["budget"]))
    if runner is None:  # kept per worker process: black-box models are trained once per seed
        runner = _RUNNERS[repr(spec["budget"])] = Runner(Budget(**spec["budget"]))
    runner.log = lines.append
    artefacts = Artefacts(spec["store"], log=lines.append, behaviour=spec["behaviour"])
    ctx = Context(spec["experiment"], spec["scale"], spec["out"], artefacts, runner,
                  list(spec["seeds"]), spec["episodes"], spec["methods"], lines.append,
                  aoc_config=dict(spec["aoc_config"]))
    return ctx, lines


_RUNNERS: dict = {}


def _prepare_task(plan, spec: dict, scale: dict, prep: tuple) -> list[dict]:
    _threads()
    ctx, _lines = worker_context(spec)
    plan.prepare(ctx, scale, prep)
    return ctx.artefacts.built


def _cell_task(plan, spec: dict, scale: dict, cell: Cell, _ready=None) -> CellResult:
    _threads()
    ctx, lines = worker_context(spec)
    result = run_cell(plan, ctx, scale, cell)
    result.log = lines
    return result


def spec_of(ctx) -> dict:
    """What a worker needs to rebuild the run's context (picklable)."""
    from dataclasses import asdict

    return {"experiment": ctx.experiment, "scale": ctx.scale, "out": ctx.out,
            "store": str(ctx.artefacts.store.root), "seeds": list(ctx.seeds),
            "behaviour": ctx.artefacts.behaviour,
            "episodes": ctx.episodes, "methods": ctx.methods,
            "aoc_config": dict(ctx.aoc_config), "budget": asdict(ctx.runner.budget)}


def run_on_ray(plan, ctx, scale: dict, cells: list[Cell], done, workers: int | None = None,
               address: str | None = None, progress=None) -> None:
    """Run ``cells`` as Ray tasks; ``done(cell, CellResult)`` as each finishes (module
    docstring: preparation first, one retry, failures reported)."""
    if not cells:
        return
    ray = start_ray(workers, address)
    spec = spec_of(ctx)
    limit = int(workers) if workers else max(1, int(ray.cluster_resources().get("CPU", 1)))
    plan_ref = ray.put(plan)
    prepare = ray.remote(num_cpus=1, max_retries=0)(_prepare_task)
    run = ray.remote(num_cpus=1, max_retries=0)(_cell_task)
    preps: dict = {}
    for cell in cells:
        if cell.prep not in preps:
            preps[cell.prep] = prepare.remote(plan_ref, spec, scale, cell.prep)
    label, n_done = f"{ctx.experiment}: {len(cells)} cells on Ray", 0
    if progress is not None:
        progress(0, len(cells), label)
    queue = [(cell, 1) for cell in cells]
    running: dict = {}
    reported: set = set()
    while queue or running:
        while queue and len(running) < limit:
            cell, attempt = queue.pop(0)
            # the first attempt waits for its group's preparation; a retry prepares itself
            ready = preps[cell.prep] if attempt == 1 else None
            running[run.remote(plan_ref, spec, scale, cell, ready)] = (cell, attempt)
        finished, _ = ray.wait(list(running), num_returns=1)
        ref = finished[0]
        cell, attempt = running.pop(ref)
        try:
            result = ray.get(ref)
        except Exception as err:  # RayTaskError, a dead worker, a failed preparation
            error = _error_text(err)
            if attempt == 1:
                ctx.say(f"{cell.label()}: failed ({error}); running it again")
                queue.append((cell, 2))
                continue
            ctx.say(f"{cell.label()}: failed twice ({error}); reported as failed")
            result = failed_result(ctx.experiment, cell, error, attempt)
        else:
            result.attempts = attempt
            for prep_ref in (preps[cell.prep],):
                if prep_ref not in reported:
                    reported.add(prep_ref)
                    try:
                        result.built = list(ray.get(prep_ref)) + result.built
                    except Exception:  # noqa: BLE001 - the cell prepared itself
                        pass
        done(cell, result)
        n_done += 1
        if progress is not None:
            progress(n_done, len(cells), label)


def _error_text(err: Exception) -> str:
    cause = getattr(err, "cause", None)
    if cause is not None and not isinstance(cause, type(err)):
        err = cause
    text = str(err).strip().splitlines()
    return f"{type(err).__name__}: {text[-1] if text else ''}"[:300]
