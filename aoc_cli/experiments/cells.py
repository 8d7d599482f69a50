"""A bench run as independent cells: one (task, method, setting, seed) each, run in order on
this machine or as Ray tasks (:mod:`aoc_cli.experiments.distributed`), and kept when finished.

An experiment is a :class:`Plan`: ``cells(ctx, scale)`` lists its cells in the order of its
rows; ``prepare(ctx, scale, prep)`` builds (or finds in the bench store) the artefacts a group
of cells shares, the corpus, models and indexes named by the cells' ``prep`` key, and returns
what ``run`` needs (the corpus); ``run(ctx, scale, cell, prepared)`` runs one cell and returns
``{"rows": [...], "extra": {...}}`` (extra: what ``finish`` needs); ``finish(ctx, scale,
[(cell, CellResult)])``, when given, draws what needs several cells; ``figure(ctx, scale)``
gives the paper's figure of a row. Every cell's run is seeded by its own seed only, so
the rows do not depend on which cells ran before, nor where.

Finished cells are written to ``OUT/cells/<key hash>.json`` (a temporary file renamed into
place) with the run's signature: the experiment, scale and parameters, the seeds, episodes,
methods and AOC settings, the bench store and a hash of aoc's own source files. A later run
with the same signature takes them instead of running them again (it resumes); any other
signature, e.g. after a code change, runs every cell again.
"""

from __future__ import annotations

import hashlib
import json
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Callable

from aoc_cli.experiments.results import result_row
from aoc_cli.report import to_jsonable
from aoc_cli.store import atomic_path


@dataclass(frozen=True)
class Cell:
    """One unit of a bench run: the rows of ``method`` on ``task`` at ``setting`` for ``seed``.

    ``prep`` names the artefacts it shares with other cells (prepared once, before them);
    ``args`` is what the experiment's ``run`` needs beyond the key (picklable)."""

    task: str
    method: str
    setting: str
    seed: int
    prep: tuple
    args: tuple = ()

    @property
    def key(self) -> tuple:
        return (self.task, self.method, self.setting, int(self.seed))

    def label(self) -> str:
        return f"{self.task} {self.method} {self.setting} seed {self.seed}"


@dataclass
class CellResult:
    """What a cell produced: result rows, plot file names, ``extra`` for the plan's finish,
    artefacts it built, messages it logged, and how many attempts it took."""

    rows: list[dict]
    plots: list[str] = field(default_factory=list)
    extra: dict = field(default_factory=dict)
    built: list[dict] = field(default_factory=list)
    log: list[str] = field(default_factory=list)
    attempts: int = 1
    failed: bool = False


@dataclass(frozen=True)
class Plan:
    """An experiment as cells (module docstring)."""

    cells: Callable
    prepare: Callable
    run: Callable
    figure: Callable
    finish: Callable | None = None


def failed_result(experiment: str, cell: Cell, error: str, attempts: int) -> CellResult:
    """A cell that failed every attempt: one row with status ``failed`` and the error."""
    return CellResult([result_row(experiment, cell.task, cell.method, cell.setting, cell.seed,
                                  status="failed", note=error)], attempts=attempts,
                      failed=True)


# -- persistence ----------------------------------------------------------------------------

def code_hash() -> str:
    """SHA-256 of aoc_cli's Python sources (path and content, sorted): a finished cell of other
    code is not taken."""
    root = Path(__file__).resolve().parent.parent
    h = hashlib.sha256()
    for path in sorted(root.rglob("*.py")):
        h.update(str(path.relative_to(root)).encode())
        h.update(path.read_bytes())
    return h.hexdigest()[:32]


def signature(ctx, scale: dict) -> dict:
    """What a finished cell must have been run with to be taken by this run."""
    return to_jsonable({"experiment": ctx.experiment, "scale": ctx.scale, "params": scale,
                        "seeds": list(ctx.seeds), "episodes": ctx.episodes,
                        "methods": ctx.methods, "aoc_config": ctx.aoc_config,
                        "budget": asdict(ctx.runner.budget),
                        "store": str(Path(ctx.artefacts.store.root).resolve()),
                        "behaviour": ctx.artefacts.behaviour,
                        "code": code_hash()})


def _cell_path(out: Path, cell: Cell) -> Path:
    digest = hashlib.sha256(json.dumps(list(cell.key)).encode()).hexdigest()[:20]
    return Path(out) / "cells" / f"{digest}.json"


def save_cell(out: Path, cell: Cell, result: CellResult, sig: dict) -> None:
    """Write a finished cell's result (a temporary file renamed into place); a cell that
    failed is not kept, so a re-run tries it again."""
    if result.failed:
        return
    path = _cell_path(out, cell)
    path.parent.mkdir(parents=True, exist_ok=True)
    record = {"key": list(cell.key), "signature": sig, "rows": result.rows,
              "plots": result.plots, "extra": result.extra, "built": result.built,
              "attempts": result.attempts}
    with atomic_path(path, suffix=".json") as tmp:
        Path(tmp).write_text(json.dumps(to_jsonable(record)) + "\n")


def load_cell(out: Path, cell: Cell, sig: dict) -> CellResult | None:
    """The cell's kept result when it was run with signature ``sig``, else None."""
    path = _cell_path(out, cell)
    try:
        record = json.loads(path.read_text())
    except (OSError, ValueError):
        return None
    if record.get("signature") != sig or record.get("key") != list(cell.key):
        return None
    return CellResult(record["rows"], record.get("plots", []), record.get("extra", {}),
                      [], [], int(record.get("attempts", 1)))


# -- running --------------------------------------------------------------------------------

def run_cell(plan: Plan, ctx, scale: dict, cell: Cell) -> CellResult:
    """Run one cell in ``ctx`` (its plots and artefacts counted from what it adds to ctx)."""
    plots0, built0 = len(ctx.plots), len(ctx.artefacts.built)
    prepared = plan.prepare(ctx, scale, cell.prep)
    out = plan.run(ctx, scale, cell, prepared)
    return CellResult(list(out.get("rows", [])), ctx.plots[plots0:], dict(out.get("extra", {})),
                      ctx.artefacts.built[built0:])
