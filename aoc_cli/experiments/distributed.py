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

from aoc_cli.experiments.cells import Cell, CellResult, failed_result, run_cell
from aoc_cli.experiments.common import Context
from aoc_cli.experiments.methods import Budget, Runner
from aoc_cli.experiments.prepare import Artefacts
from aoc_cli.parallel import as_completed, capacity, error_text, start_ray


def _threads() -> None:
    import faiss
    import torch

    torch.set_num_threads(1)
    faiss.omp_set_num_threads(1)


def worker_context(spec: dict):
    """The Context of a worker: the run's settings, this worker's own artefacts and runner."""
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

    def submit(cell, attempt):
        # the first attempt waits for its group's preparation; a retry prepares itself
        ready = preps[cell.prep] if attempt == 1 else None
        return run.remote(plan_ref, spec, scale, cell, ready)

    reported: set = set()
    for cell, attempt, result, err in as_completed(ray, submit, cells,
                                                   limit=capacity(ray, workers), attempts=2):
        if err is not None:  # RayTaskError, a dead worker, a failed preparation
            error = error_text(err)
            if attempt == 1:
                ctx.say(f"{cell.label()}: failed ({error}); running it again")
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
