"""Value-mode `aoc evaluate` on an icu-sepsis log with the offline policy evaluation (issue 26):
held-out steps per second, where the time goes, and the decisions checked step by step.

    OMP_NUM_THREADS=1 .venv/bin/python benchmarks/perf/evaluate_ope.py [--model task|paper]
        [--store DIR] [--repeats 3] [--per-step-episodes 200] [--cases a,b] [--fqe-steps N,...]
        [--fqe-processes N,...]
        [-f json]

The store (``--store``, default /tmp/aoc-evaluate-sepsis) is laid out as
``benchmarks/perf/ope_sepsis.py``'s (built here when missing, through the API
entries of the commands): a corpus ``train`` of 10,000 clinician episodes and a held-out log
``held0`` of 5,000 (seed 1000; ``--held-episodes N``: ``held0-N`` of N episodes).
``--model task`` (the default) times ``aoc evaluate`` as a
user runs it after ``aoc collect icu-sepsis``, ``aoc train NAME`` and ``aoc index NAME`` with no
flags: the model ``default`` (fqe values, gamma 1, history 0) and the task's controller
(residual cap 0.01, support penalty 5), as ``aoc_cli.open_session`` opens them.
``--model paper``: a model ``paper`` on the same corpus with the paper's value target (the
return, gamma 0.99, history 0) and the paper's controller settings (what this benchmark timed
before). Times :func:`aoc_cli.evaluation.score.score_log` in this process (the session opened
once before; 25 candidate actions a step, the knn and bc baselines), wall and CPU seconds
(user + system of this process and of FQE's forked parts: what the wall figure would be on
one idle core),
the median of ``--repeats`` runs, the cases interleaved round by round. Each row splits its
time into the value targets of the held-out log (value_r2's target: for fqe values a fitted Q
evaluation of the log), the OPE, and the rest (the decisions and the baselines):

* ``per step``: every held-out step decided on its own (the path before deciding each distinct
  observation once), on the first ``--per-step-episodes`` episodes; before the timings, its
  decisions are compared with the distinct path's on those steps (the same actions, the same
  supporting rows, weights and residuals within 1e-9), printed to stderr;
* ``distinct``: each distinct observation decided once, no OPE (``--ope none``);

(these two read the held-out log's targets kept by an earlier run: they time the decisions)
* ``ope fitted before``: ``aoc evaluate``'s default (PDWIS, WDR, FQE with its
  refits, for the controller and both baselines) as it ran before issue 26's speed work: the
  held-out log's targets computed by each run, Adam's per-tensor loop (the targets' FQE and
  the OPE's ensemble), the ensemble's next actions by the (M, B, n) comparison;
* ``ope fitted``: the first ``aoc evaluate`` of a log now (targets computed, then
  kept beside the log; Adam in one call; a deterministic policy's next action read off);
* ``ope kept before`` / ``ope kept``: every later ``aoc evaluate`` of the
  same log (any model or controller of the same value target reads them back), the OPE as
  before / now;
* ``ope kept, fqe N steps``: the latter with FQE's fit at N gradient steps instead of
  its default (``--fqe-steps N,...``, e.g. the default before, to time a change of it in one run);
* ``ope kept, N processes``: the latter with FQE's ensembles trained in N processes instead of
  the default's (the cores, at most 4; ``--fqe-processes N,...``: 1 is the one-process run);
* ``ope fitted aoc targets``: a log's first evaluate with value_r2's held-out target for fqe
  values fitted by aoc's own fitted Q evaluation, as the model's values were (60 backups of 300
  steps; what ``aoc evaluate`` did before the OPE's FQE fitted the logged behaviour beside the
  policies).

The "before" cases put back earlier code paths by patching this process (Adam's per-tensor
loop, the ensemble's general next-action draw); the targets' stage times both of
``aoc evaluate``'s held-out targets (aoc's FQE and the logged behaviour's by the OPE's).
"""

from __future__ import annotations

import shutil
import sys

import _harness as h

h.omp_threads(1)

import numpy as np  # noqa: E402
import ope_sepsis  # noqa: E402
import torch  # noqa: E402

import aoc_cli  # noqa: E402
from aoc_cli.belief import targets as tg  # noqa: E402
from aoc_cli.control import ControllerConfig, open_session  # noqa: E402
from aoc_cli.evaluation import context as ei  # noqa: E402
from aoc_cli.evaluation import score as ev  # noqa: E402
from aoc_cli.ope import ensemble as ens  # noqa: E402
from aoc_cli.ope.evaluate_block import OPESettings  # noqa: E402
from aoc_cli.store import Store, targets_dir  # noqa: E402
from aoc_cli.threads import one_thread  # noqa: E402

#: The paper's value target, on the task's corpus (what this benchmark timed first).
PAPER_VALUE = {"value": "return", "gamma": 0.99, "history_length": 0}
CASES = ("per step", "distinct", "ope fitted before", "ope fitted",
         "ope kept before", "ope kept", "ope fitted aoc targets")


def prepare(store: Store, model: str, held_episodes: int = 5000):
    """(corpus, held-out log, session) of ``--model``."""
    corpus = ope_sepsis.prepare(store, 10_000)
    if model == "paper":
        corpus = h.corpus_ready(store, "train", train=dict(seed=0, **PAPER_VALUE),
                                model="paper", index={})
        session = open_session(corpus, "paper", config=ControllerConfig())
    else:
        session = aoc_cli.open_session(corpus.name, store=store)  # the task's settings
    name = "held0" if held_episodes == 5000 else f"held0-{held_episodes}"
    held = h.corpus_ready(store, name, "icu-sepsis", episodes=held_episodes, seed=1000)
    return corpus, held, session


class Stages:
    """Seconds (wall, CPU) spent in the held-out targets, summed over a run."""

    def __init__(self):
        self.wall = self.cpu = 0.0
        self.real, self.behaviour = ei.held_out_targets, ei.behaviour_targets

        def timer(real):
            def timed(*args, **kwargs):
                out, wall, cpu = h.timed(lambda: real(*args, **kwargs))
                self.wall += wall
                self.cpu += cpu
                return out
            return timed

        ei.held_out_targets = timer(self.real)
        ei.behaviour_targets = self.timed_behaviour = timer(self.behaviour)

    def reset(self):
        self.wall = self.cpu = 0.0


def per_step_check(session, few) -> str:
    """The per-step path against the distinct path on the steps of ``few``: one line."""
    with one_thread():
        ctx = ei.EvalContext.build(session, few, ["knn", "bc"])
        rows = np.arange(few.n_rows)
        ep = np.searchsorted(ctx.data_starts, rows, side="right") - 1
        args = (rows, ep, ctx.data_obs, ctx.data.history(rows, ctx.history_length),
                ctx.data_actions)
        a, b = ev._value(ctx, *args), ev._value_distinct(ctx, *args)
    same = np.array_equal(a.decided, b.decided) and np.array_equal(a.support_rows,
                                                                   b.support_rows)
    w = float(np.abs(a.support_weights - b.support_weights).max())
    r = float(np.abs(a.residual - b.residual).max())
    v = float(np.abs(a.v_hat - b.v_hat).max())
    ok = same and max(w, r, v) <= 1e-9
    return (f"per step vs distinct on {few.n_rows} steps: actions and supporting rows "
            f"{'identical' if same else 'DIFFER'}; max |weight| diff {w:.1e}, residual "
            f"{r:.1e}, v_hat {v:.1e}: {'same decisions' if ok else 'NOT THE SAME'}")


def main() -> None:
    ap = h.parser(__doc__, repeats=3)
    ap.add_argument("--model", choices=("task", "paper"), default="task")
    ap.add_argument("--store", default="/tmp/aoc-evaluate-sepsis")
    ap.add_argument("--per-step-episodes", type=int, default=200)
    ap.add_argument("--held-episodes", type=int, default=5000,
                    help="episodes of the held-out log (5,000: held0; else held0-N, seed 1000)")
    ap.add_argument("--cases", default=",".join(CASES),
                    help="comma-separated, of: " + ", ".join(CASES))
    ap.add_argument("--fqe-steps", default="",
                    help="also 'ope kept' with FQE at these gradient steps (N,...)")
    ap.add_argument("--fqe-processes", default="",
                    help="also 'ope kept' with FQE's ensembles in these processes (N,...)")
    args = ap.parse_args()
    store = Store(args.store)
    corpus, held, session = prepare(store, args.model, args.held_episodes)
    first = f"{held.name}-first{args.per_step_episodes}"  # the first episodes of held
    if not store.exists(first):
        store.write(first, held.load().select_episodes(
            np.arange(held.n_episodes) < args.per_step_episodes))
    few = store.corpus(first)
    print(per_step_check(session, few), file=sys.stderr)
    stages = Stages()
    kept = targets_dir(held.path)
    none, full = OPESettings(estimators=()), OPESettings()
    adam, deterministic = torch.optim.Adam, ens._deterministic

    def case(name):
        data = few if name == "per step" else held
        ope = none if name in ("per step", "distinct") else full
        if " fqe " in name:
            ope = OPESettings(fqe_steps=int(name.split(" fqe ")[1].split()[0]))
        if name.endswith(" processes"):
            ope = OPESettings(fqe_processes=int(name.split(", ")[1].split()[0]))

        def run(_i):
            if name.startswith("ope fitted"):
                shutil.rmtree(kept, ignore_errors=True)   # as a log evaluated the first time
            stages.reset()
            if name == "ope fitted aoc targets":
                ei.behaviour_targets = lambda *a, **kw: None
            if name == "per step":
                ev._value_distinct = lambda ctx, *a: _per_step(ctx, *a)
                ev.chunk_size = lambda ctx, chunk_steps=ev.CHUNK_STEPS: chunk_steps
            if name.endswith("before"):
                torch.optim.Adam = lambda *a, **kw: adam(*a, **{**kw, "foreach": False,
                                                                 "fused": False})
                ens._deterministic = lambda _cums: None
            try:
                summary = ev.score_log(session, data, ["knn", "bc"], ope=ope)[0]
                return {**summary, "targets_wall": stages.wall, "targets_cpu": stages.cpu}
            finally:
                ev._value_distinct, ev.chunk_size = _distinct, _chunk_size
                torch.optim.Adam, ens._deterministic = adam, deterministic
                ei.behaviour_targets = stages.timed_behaviour

        return data, run

    names = [c.strip() for c in args.cases.split(",") if c.strip()]
    if any(n not in CASES for n in names):
        ap.error(f"unknown case in {args.cases!r}: use {', '.join(CASES)}")
    names += [f"ope kept, fqe {int(n)} steps" for n in args.fqe_steps.split(",") if n]
    names += [f"ope kept, {int(n)} processes" for n in args.fqe_processes.split(",") if n]
    # kept by an earlier evaluate (and by each fitted case): the decisions' rows read them
    for data in (held, few):
        value, gamma = value_spec(session)
        if value != "fqe" or stages.behaviour(data, gamma, full.seed) is None:
            stages.real(data, value, gamma)
    made = {name: case(name) for name in names}
    runs = h.interleave({name: run for name, (_d, run) in made.items()}, args.repeats)
    rows = []
    for name in names:
        data, r = made[name][0], runs[name]
        med = lambda key: float(np.median([o[key] for o in r.outs]))
        rows.append(h.row(name, data.n_rows, r, unit="steps",
                          steps_per_cpu_s=data.n_rows / r.cpu_median,
                          targets_cpu_s=med("targets_cpu"), ope_wall_s=med("ope_seconds"),
                          value_r2=round(r.out.get("value_r2", float("nan")), 4)))
    h.emit(rows, args.format)


def value_spec(session) -> tuple:
    """(value, gamma) of the session's model, as ``aoc evaluate`` reads them."""
    spec = session.model.meta.get("value") or {}
    return spec.get("target", "return"), float(spec.get("gamma", 0.99))


def _per_step(ctx, rows, ep, obs, hist, logged):
    out = ev._value(ctx, rows, ep, obs, hist, logged)
    if "knn" in ctx.baselines:
        out.baselines["knn"] = ctx.knn.predict(ctx, obs, logged, ep)
    return out


_distinct, _chunk_size = ev._value_distinct, ev.chunk_size

if __name__ == "__main__":
    main()
