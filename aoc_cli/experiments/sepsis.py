"""`aoc bench icu-sepsis`: AOC beside the baselines on logs of the clinicians, valued exactly.

For each log size (episodes of the clinicians' policy, ``aoc collect icu-sepsis``) and seed:

* **aoc** -- AOC as a user gets it: ``aoc train NAME`` and ``aoc index NAME`` with no flags
  (run as commands: the settings they decide from the log's evidence), and the controller
  with the settings saved with the model (as ``aoc explain`` and ``aoc rollout`` use them);
* **knn** -- nearest-neighbour Q on the raw (observation, action) features, k = d_b + 1, with
  AOC's row values (the ``knn`` baseline of ``aoc rollout``);
* **cql**, **bcq** -- d3rlpy's DiscreteCQL and DiscreteBCQ on the same features and rewards;
* **bc** -- behaviour cloning (the log's modal action per observation,
  :mod:`aoc_cli.baselines.sepsis_policies`);
* **tabular** -- reference, told the state: the behaviour's Q in a count model of the log,
  greedy over actions logged at least 10 times;
* **spibb** -- the peer to beat, told the state: Pi_b-SPIBB (safe policy improvement with
  baseline bootstrapping) on the log's count model, its threshold N_wedge chosen by a rule on
  the log's held-out halves (:mod:`aoc_cli.baselines.spibb`); a stochastic policy, valued
  exactly;
* **clinicians** (the behaviour), **modal** (their most frequent action), **random**,
  **one-step** (argmax of the clinicians' exact Q on their support: what a perfect AOC reaches)
  and **optimal** (value iteration): references from the package's tables, the same at every
  size.

A policy with history length 0 is a state policy: every live state's observation is decided
once and the policy valued exactly (``kind`` exact); one that reads a history is rolled out in
the package's environment (``kind`` monte-carlo, with a 95% interval). Each state policy's
agreement with the one-step oracle's action over the 713 live states is reported too.

Writes ``results.csv``, ``summary.json`` and ``summary.md`` to ``out``.
"""

from __future__ import annotations

import json
import time
from pathlib import Path

import numpy as np

from aoc_cli.baselines import make_baseline
from aoc_cli.baselines import sepsis_policies as sp
from aoc_cli.baselines.offline_rl import OfflineRLConfig
from aoc_cli.baselines.spibb import spibb_policy
from aoc_cli.control import open_session
from aoc_cli.envs import collect, make_env
from aoc_cli.envs.icu_sepsis import STRATEGIES
from aoc_cli.envs.icu_sepsis import tables as sepsis_tables
from aoc_cli.envs.tabular import greedy
from aoc_cli.errors import AocError, BadSetting, param
from aoc_cli.experiments.results import write_rows_csv
from aoc_cli.index import build_index
from aoc_cli.store import DEFAULT_MODEL, Store, atomic_path
from aoc_cli.training.fit import train_corpus

SCALES = {
    "full": {"sizes": (1000, 10000, 50000), "cql_steps": 10000, "mc_episodes": 1000},
    "quick": {"sizes": (1000, 5000), "cql_steps": 3000, "mc_episodes": 300},
    "tiny": {"sizes": (200,), "cql_steps": 200, "mc_episodes": 10},
}
LEARNT = ("aoc", "knn", "cql", "bcq", "bc", "tabular", "spibb")
REFERENCES = ("clinicians", "modal", "random", "one-step", "optimal")
METHODS = LEARNT + REFERENCES
TASKS = ("icu-sepsis", "icu-sepsis-terminate")


def references(tables) -> dict[str, dict]:
    """The reference policies' exact values (and state policies where deterministic)."""
    mdp = tables.mdp
    one_step = greedy(mdp.q_values(tables.clinicians), tables.clinicians > 0)
    _v, optimal = mdp.optimal()
    out = {"clinicians": {**sp.exact(tables, tables.clinicians), "policy": None},
           "random": {**sp.exact(tables, tables.behaviour("random")), "policy": None}}
    for name, pol in (("modal", tables.modal()), ("one-step", one_step), ("optimal", optimal)):
        out[name] = {**sp.exact(tables, pol), **sp.inadmissible(tables, pol), "policy": pol}
    return out


def train_aoc(store_root: Path, name: str, seed: int = 0) -> dict:
    """AOC as a user gets it: what ``aoc train NAME --seed S`` does with no other flag (the
    settings it takes from the task or chooses from the log: the one training path,
    :func:`aoc_cli.training.fit.train_corpus`) and ``aoc index NAME``; the training metrics."""
    corpus = Store.open(store_root).corpus(name)
    metrics = train_corpus(corpus, seed=seed, overwrite=True,
                           choose_controller=True).metrics
    build_index(corpus)
    return metrics


def _support(decisions: list) -> dict:
    rows = [len(d.support_rows) for d in decisions if getattr(d, "support_rows", None) is not None]
    return {"support_rows_mean": float(np.mean(rows)) if rows else None,
            "support_rows_max": int(np.max(rows)) if rows else None}


def run_size(store, task: str, episodes: int, seed: int, cfg: dict, methods: list[str],
             tables, refs: dict, log=None) -> list[dict]:
    """One log: every learnt method's value (exact or Monte-Carlo) on it."""
    name = f"{task}-{episodes}-s{seed}"
    data, _summary = collect(task, episodes=episodes, seed=seed)
    corpus = store.write(name, data, overwrite=True)
    oracle = refs["one-step"]["policy"]
    rows: list[dict] = []

    def record(method: str, result: dict, seconds: float, policy=None, **extra):
        rec = {"task": task, "episodes": episodes, "rows": corpus.n_rows, "seed": seed,
               "method": method, "value": result["value"], "low": result["low"],
               "high": result["high"], "kind": result["kind"],
               "agree_one_step": None if policy is None
               else float(np.mean(policy[:sp.LIVE] == oracle[:sp.LIVE])),
               **({} if policy is None else sp.inadmissible(tables, policy)),
               "seconds": seconds, **extra}
        rows.append(rec)
        if log is not None:
            log(f"{name}: {method} {result['value']:.4f} ({result['kind']})")

    needs_session = [m for m in methods if m in ("aoc", "knn", "cql", "bcq")]
    session, L, env = None, 0, make_env(task)
    if needs_session:
        started = time.perf_counter()
        metrics = train_aoc(store.root, name, seed=seed)
        session = open_session(corpus, DEFAULT_MODEL)  # the model's own controller settings
        L = session.history_length
        train_seconds = time.perf_counter() - started
        chosen = (metrics.get("selection") or {}).get("chosen") or {}
    for method in methods:
        started = time.perf_counter()
        if method == "spibb":
            pol, rule = spibb_policy(data.columns["state"].astype(np.int64), data.actions,
                                     data.rewards, data.terminals, data.episode_starts, seed)
            record(method, sp.exact(tables, pol), time.perf_counter() - started, None,
                   n_wedge=rule["n_wedge"])
            continue
        if method in ("bc", "tabular"):
            if method == "bc":
                pol = sp.bc_policy(corpus.observations, corpus.actions, tables)
            else:
                pol = sp.tabular_policy(data.columns["state"].astype(np.int64),
                                        np.asarray(data.actions, np.int64), data.rewards,
                                        data.terminals, data.episode_starts)
            record(method, sp.exact(tables, pol), time.perf_counter() - started, pol)
            continue
        if method == "aoc":
            decide = session.controller.decide
            extra = {"history_length": L, "val_r2": metrics.get("val_r2"),
                     "train_seconds": train_seconds,
                     **{k: v for k, v in chosen.items() if k in ("hidden", "weight_decay")}}
        else:
            options = {"config": OfflineRLConfig(steps=int(cfg["cql_steps"]), seed=seed,
                                                 threads=1)} if method in ("cql", "bcq") else {}
            baseline = make_baseline(method, session, env, seed=seed, **options)
            decide, extra = baseline.decide, {}
        if L == 0:
            decisions = []

            def keep(observation, history, _decide=decide):
                out = _decide(observation, history)
                decisions.append(out)
                return out

            pol = sp.state_policy(keep, tables, 0)
            record(method, sp.exact(tables, pol), time.perf_counter() - started, pol,
                   **extra, **(_support(decisions) if method == "aoc" else {}))
        else:
            result = sp.monte_carlo(None if method == "aoc" else decide, session, env,
                                    int(cfg["mc_episodes"]), seed=10_000 * (seed + 1))
            record(method, result, time.perf_counter() - started, None, **extra)
    return rows


def summarise(rows: list[dict], refs: dict, methods: list[str]) -> list[dict]:
    """Per method and size: the mean value over seeds (and the interval of one seed)."""
    out = []
    sizes = sorted({r["episodes"] for r in rows})
    for method in methods:
        if method in REFERENCES:
            ref = refs[method]
            out.append({"method": method, "episodes": None, "seeds": 0, "value": ref["value"],
                        "low": ref["low"], "high": ref["high"], "kind": "exact",
                        "agree_one_step": None, "inadmissible_states": ref.get(
                            "inadmissible_states")})
            continue
        for size in sizes:
            mine = [r for r in rows if r["method"] == method and r["episodes"] == size]
            if not mine:
                continue
            agree = [r["agree_one_step"] for r in mine if r["agree_one_step"] is not None]
            fatal = [r["inadmissible_states"] for r in mine if "inadmissible_states" in r]
            out.append({"method": method, "episodes": size, "seeds": len(mine),
                        "value": float(np.mean([r["value"] for r in mine])),
                        "low": float(np.mean([r["low"] for r in mine])),
                        "high": float(np.mean([r["high"] for r in mine])),
                        "kind": mine[0]["kind"],
                        "agree_one_step": float(np.mean(agree)) if agree else None,
                        "inadmissible_states": float(np.mean(fatal)) if fatal else None})
    return out


def markdown(summary: list[dict]) -> str:
    lines = ["| method | episodes | seeds | value | 95% interval | kind | agrees with one-step "
             "| inadmissible doses (share of states) |",
             "| --- | --- | --- | --- | --- | --- | --- | --- |"]
    for s in summary:
        interval = "" if s["kind"] == "exact" else f"{s['low']:.3f} - {s['high']:.3f}"
        agree = "" if s["agree_one_step"] is None else f"{s['agree_one_step']:.2f}"
        fatal = "" if s.get("inadmissible_states") is None else f"{s['inadmissible_states']:.3f}"
        lines.append(f"| {s['method']} | {s['episodes'] or 'tables'} | {s['seeds']} | "
                     f"{s['value']:.4f} | {interval} | {s['kind']} | {agree} | {fatal} |")
    return "\n".join(lines) + "\n"


def run_sepsis(out: Path, bench_store: Path, scale: str = "full", seeds: int | None = None,
               methods: list[str] | None = None, sizes: list[int] | None = None,
               task: str = "icu-sepsis", log=None, progress=None) -> dict:
    """Run every size and seed, write the outputs; the report."""
    if task not in TASKS:
        raise AocError(f"unknown icu-sepsis task {task!r}: use {' or '.join(TASKS)}")
    if scale not in SCALES:
        raise AocError(f"unknown scale {scale!r}: use {', '.join(SCALES)}")
    methods = list(methods or METHODS)
    unknown = [m for m in methods if m not in METHODS]
    if unknown:
        raise BadSetting("methods", methods, f"{param('methods')}: unknown {', '.join(unknown)}; "
                         f"use {', '.join(METHODS)}")
    if seeds is not None and seeds < 1:
        raise BadSetting("seeds", seeds, f"{param('seeds')} must be >= 1, got {seeds}")
    cfg = SCALES[scale]
    sizes = list(sizes or cfg["sizes"])
    if any(s < 1 for s in sizes):
        raise BadSetting("sizes", sizes, f"{param('sizes')}: episodes per log must be >= 1, "
                         f"got {sizes}")
    n_seeds = int(seeds or 1)
    started = time.perf_counter()
    tables = sepsis_tables(STRATEGIES[task])
    refs = references(tables)
    store = Store(Path(bench_store))
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    learnt = [m for m in methods if m in LEARNT]
    rows: list[dict] = []
    cells = [(size, seed) for size in sizes for seed in range(n_seeds)]
    for i, (size, seed) in enumerate(cells):
        if progress is not None:
            progress(i, len(cells), f"bench {task}: {size} episodes, seed {seed}")
        if learnt:
            rows += run_size(store, task, size, seed, cfg, learnt, tables, refs, log)
    if progress is not None:
        progress(len(cells), len(cells), f"bench {task}")
    summary = summarise(rows, refs, methods)
    write_rows_csv(out / "results.csv", rows)
    with atomic_path(out / "summary.json", suffix=".json") as tmp:
        Path(tmp).write_text(json.dumps({"task": task, "scale": scale, "sizes": sizes,
                                         "seeds": n_seeds, "summary": summary, "rows": rows},
                                        indent=2))
    with atomic_path(out / "summary.md", suffix=".md") as tmp:
        Path(tmp).write_text(markdown(summary))
    return {"summary": summary, "rows": rows, "out": str(out),
            "seconds": time.perf_counter() - started}
