"""Run an experiment's plan: every cell here one after the other, or as Ray tasks
(:mod:`aoc_cli.experiments.distributed`); cells finished by an earlier run are kept
(:mod:`aoc_cli.experiments.cells`)."""

from __future__ import annotations

from aoc_cli.experiments.cells import (CellResult, Plan, load_cell, run_cell, save_cell,
                                       signature)
from aoc_cli.experiments.distributed import run_on_ray


def execute(plan: Plan, ctx, scale: dict, workers: int | None = None,
            address: str | None = None, progress=None) -> list[dict]:
    """Run every cell of ``plan`` (kept ones are taken), in order here or on Ray with
    ``workers`` / ``address``; write each finished cell; run ``finish``; return the rows in
    the plan's order. ``ctx.plots`` and ``ctx.artefacts.built`` collect every cell's."""
    cells = list(plan.cells(ctx, scale))
    keys = [c.key for c in cells]
    if len(set(keys)) != len(keys):
        raise RuntimeError(f"{ctx.experiment}: two cells share a key")
    sig = signature(ctx, scale)
    results: dict[tuple, CellResult] = {}
    for cell in cells:
        kept = load_cell(ctx.out, cell, sig)
        if kept is not None:
            results[cell.key] = kept
    pending = [c for c in cells if c.key not in results]
    if results:
        ctx.say(f"{ctx.experiment}: {len(results)} of {len(cells)} cells kept from an earlier "
                f"run in {ctx.out / 'cells'}; running {len(pending)}")
    if workers is None and address is None:
        for cell in pending:
            results[cell.key] = run_cell(plan, ctx, scale, cell)
            save_cell(ctx.out, cell, results[cell.key], sig)
    else:
        def done(cell, result):
            results[cell.key] = result
            save_cell(ctx.out, cell, result, sig)
            ctx.artefacts.built.extend(result.built)
            for line in result.log:
                ctx.say(line)

        run_on_ray(plan, ctx, scale, pending, done, workers=workers, address=address,
                   progress=progress)
    ordered = [results[c.key] for c in cells]
    ctx.plots[:] = list(dict.fromkeys(p for r in ordered for p in r.plots))
    if plan.finish is not None:
        plan.finish(ctx, scale, list(zip(cells, ordered)))
    return [row for r in ordered for row in r.rows]
