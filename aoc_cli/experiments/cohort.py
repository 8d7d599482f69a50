"""`aoc bench icu-cohort`: AOC beside its peers on the cohort test bed, by true survival.

The test bed (:mod:`aoc_cli.envs.icu_cohort`): a cohort of the clinicians' ICU stays drawn from
the ICU-Sepsis MDP, each row the 47 features of its state's cluster centre plus Gaussian noise
(sd ``noise``), 15% of the cells empty and held forward, 3% of the stays censored. For each
size (stays), noise and seed the log is collected (:func:`~aoc_cli.envs.icu_cohort.collect_data`:
the arrays ``aoc ingest`` makes of the cohort's CSV) into the bench store, and each method's true
survival is measured:

* **aoc** -- AOC as a user gets it: what ``aoc train NAME`` does with no other flag
  (:func:`aoc_cli.training.fit.train_corpus`, the controller chosen on validation episodes)
  and ``aoc index NAME``, the controller with the model's own settings deciding whole batches
  of episodes (:class:`aoc_cli.control.batch.BatchPolicy`);
* **bc**, **cql** -- d3rlpy's DiscreteBC and DiscreteCQL (the ``bench`` extra) on the same
  standardised observations (gaps held forward, as in the corpus), actions, rewards and ends;
* **spibb** -- Pi_b-SPIBB *told the state*: the log's true states (the corpus column
  ``state``, which no other learnt method reads), the log's count model, its threshold chosen
  on the log's halves (:func:`aoc_cli.baselines.spibb.spibb_policy`): an upper reference of
  what a learner that could read the state through the noise would do;
* references: **clinicians** (their policy in the true state, the log's behaviour: exact),
  **clinicians-nearest** (their probabilities in the state whose cluster centre is nearest the
  noisy observation: what their own policy does when it too reads the features),
  **modal-nearest** and **optimal-nearest** (their modal dose and the MDP's optimal policy
  through the nearest centre), **optimal** (the MDP's optimum, told the state: exact).

A policy that reads the features is rolled out in the MDP through the same noise, gaps and
hold (:func:`~aoc_cli.envs.icu_cohort.rollout_value`, ``episodes`` a cell, 95% interval); every
such method of a (size, noise, seed) cell runs on the same rollout seed, so the values are
paired, and each is set against AOC: AOC's survival less its own, with the interval of the
per-episode differences (:func:`against_aoc`). A state policy (spibb, clinicians, optimal) is
valued exactly.

Writes ``results.csv``, ``summary.json`` and ``summary.md`` to ``out``.
"""

from __future__ import annotations

import json
import math
import time
from pathlib import Path

import numpy as np

from aoc_cli.baselines import sepsis_policies as sp
from aoc_cli.baselines.common import MissingExtra
from aoc_cli.baselines.offline_rl import OfflineRLConfig, train_agent
from aoc_cli.baselines.spibb import spibb_policy
from aoc_cli.control import open_session
from aoc_cli.control.batch import BatchPolicy
from aoc_cli.envs import icu_cohort as cohort
from aoc_cli.errors import AocError, BadSetting, param
from aoc_cli.experiments.results import write_rows_csv
from aoc_cli.index import build_index
from aoc_cli.store import DEFAULT_MODEL, Store, atomic_path
from aoc_cli.threads import thread_limits
from aoc_cli.training.fit import train_corpus

TASK = "icu-cohort"
SCALES = {
    "full": {"sizes": (1000, 10000, 50000), "noises": (0.0, 0.3, 1.0), "cql_steps": 20_000,
             "bc_steps": 10_000, "episodes": 20_000},
    "quick": {"sizes": (1000, 5000), "noises": (0.3,), "cql_steps": 5000, "bc_steps": 3000,
              "episodes": 500},
    "tiny": {"sizes": (200,), "noises": (0.3,), "cql_steps": 200, "bc_steps": 200,
             "episodes": 100},
}
LEARNT = ("aoc", "bc", "cql", "spibb")
REFERENCES = ("clinicians", "clinicians-nearest", "modal-nearest", "optimal-nearest",
              "optimal")
METHODS = LEARNT + REFERENCES
#: What each method decides from.
SEES = {"aoc": "noisy features", "bc": "noisy features", "cql": "noisy features",
        "spibb": "told the state", "clinicians": "told the state",
        "clinicians-nearest": "nearest centre", "modal-nearest": "nearest centre",
        "optimal-nearest": "nearest centre", "optimal": "told the state"}
D3RLPY = ("bc", "cql")
#: AOC's survival less a method's, and its 95% interval (:func:`against_aoc`).
DIFFERENCE = ("aoc_minus", "aoc_minus_low", "aoc_minus_high")


def rollout_seed(seed: int) -> int:
    """The rollout seed of every Monte-Carlo method of a cell with log seed ``seed``."""
    return 10_000 * (int(seed) + 1)


def train_aoc(corpus, seed: int = 0, threads: int | None = None) -> tuple[dict, object]:
    """What ``aoc train NAME --seed S`` does with no other flag (``threads``: its
    ``--threads``) and ``aoc index NAME``; the training metrics and the session opened with
    the model's own controller settings."""
    extra = {"threads": int(threads)} if threads else {}
    metrics = train_corpus(corpus, seed=seed, overwrite=True, choose_controller=True,
                           **extra).metrics
    build_index(corpus)
    return metrics, open_session(corpus, DEFAULT_MODEL)


def d3rlpy_decide(algo: str, corpus, steps: int, seed: int):
    """A ``decide_batch`` of d3rlpy's discrete ``algo`` (bc | cql) trained ``steps`` steps on
    the corpus's standardised observations, one torch thread."""
    agent, features = train_agent(algo, corpus, 0, OfflineRLConfig(steps=int(steps),
                                                                    seed=seed, threads=1))

    def decide(obs: np.ndarray) -> np.ndarray:
        with thread_limits(torch=1):
            return np.asarray(agent.predict(features.transform(obs, None, None)), np.int64)

    return decide


def _exact(value: float) -> dict:
    return {"value": float(value), "low": float(value), "high": float(value), "kind": "exact"}


def run_cell(store: Store, stays: int, noise: float, seed: int, cfg: dict, methods: list[str],
             episodes: int, threads: int | None = None, cache: dict | None = None,
             log=None) -> list[dict]:
    """One cohort (``stays`` stays at ``noise``, log seed ``seed``): each method's row."""
    tables = cohort.sepsis.tables("mean")
    cache = {} if cache is None else cache
    name = f"{TASK}-{stays}-n{noise:g}-s{seed}"
    data, _summary = cohort.collect_data(episodes=stays, seed=seed, noise=noise)
    learners = [m for m in methods if m in ("aoc", *D3RLPY)]
    corpus = store.write(name, data, overwrite=True) if learners else None
    n_rows = int(len(data.actions))
    rseed = rollout_seed(seed)
    rows: list[dict] = []
    survived: dict[str, np.ndarray] = {}     # each rolled-out method's (episodes,) outcomes

    def rolled(decide) -> dict:
        return {**cohort.rollout_value(decide, episodes, noise=noise, seed=rseed),
                "kind": "monte-carlo"}

    def record(method: str, result: dict | None, started: float, note: str = "", **extra):
        ok = result is not None
        if ok and "survived" in result:
            survived[method] = result["survived"]
        rows.append({"task": TASK, "stays": stays, "noise": noise, "rows": n_rows,
                     "seed": seed, "method": method, "sees": SEES[method],
                     "value": result["value"] if ok else None,
                     "low": result["low"] if ok else None,
                     "high": result["high"] if ok else None,
                     "kind": result["kind"] if ok else None,
                     "episodes": episodes if ok and result["kind"] == "monte-carlo" else None,
                     "rollout_seed": rseed if ok and result["kind"] == "monte-carlo" else None,
                     "status": "ok" if ok else "skipped", "note": note,
                     "seconds": time.perf_counter() - started, **extra})
        if log is not None:
            log(f"{name}: {method} " + (f"{result['value']:.4f} ({result['kind']})" if ok
                                        else f"skipped ({note})"))

    optimal = cohort.optimal_state_policy()
    nearest = {"clinicians-nearest": tables.clinicians, "modal-nearest": tables.modal(),
               "optimal-nearest": optimal}
    for method in methods:
        started = time.perf_counter()
        if method == "aoc":
            metrics, session = train_aoc(corpus, seed, threads)
            trained = time.perf_counter() - started
            chosen = (metrics.get("selection") or {}).get("chosen") or {}
            result = rolled(BatchPolicy(session.controller))
            record(method, result, started, history_length=session.history_length,
                   val_r2=metrics.get("val_r2"), train_seconds=trained,
                   **{k: v for k, v in chosen.items() if k in ("hidden", "weight_decay")})
        elif method in D3RLPY:
            steps = int(cfg[f"{method}_steps"])
            try:
                decide = d3rlpy_decide(method, corpus, steps, seed)
            except MissingExtra as err:
                record(method, None, started, str(err))
                continue
            record(method, rolled(decide), started, steps=steps)
        elif method == "spibb":
            pol, rule = spibb_policy(data.columns["state"].astype(np.int64), data.actions,
                                     data.rewards, data.terminals, data.episode_starts, seed)
            record(method, _exact(tables.mdp.value(pol)), started, n_wedge=rule["n_wedge"])
        elif method == "clinicians":
            record(method, _exact(cohort.clinicians_value()), started)
        elif method == "optimal":
            record(method, _exact(tables.mdp.value(optimal)), started)
        else:  # a state policy through the nearest centre: the same at every size
            key = (method, noise, rseed, episodes)
            if key not in cache:
                cache[key] = rolled(cohort.nearest_centre_policy(nearest[method], seed=rseed))
            record(method, cache[key], started)
    return against_aoc(rows, survived)


def against_aoc(rows: list[dict], survived: dict[str, np.ndarray]) -> list[dict]:
    """Each row of one cell with ``aoc_minus`` (AOC's survival less the method's) and its 95%
    interval ``aoc_minus_low/high``: for a rolled-out method the paired difference over the
    same episodes (:func:`~aoc_cli.envs.icu_cohort.paired_difference`), for an exact one AOC's
    own interval less the exact value; ``aoc_minus_kind`` says which (None where AOC or the
    method was not run). ``ahead`` reads the interval: "shown ahead", "shown behind" or "not
    shown apart"."""
    aoc = next((r for r in rows if r["method"] == "aoc" and r["status"] == "ok"), None)
    for r in rows:
        diff, kind = None, None
        if aoc is not None and r is not aoc and r["status"] == "ok":
            if r["kind"] == "monte-carlo":
                p = cohort.paired_difference(survived["aoc"], survived[r["method"]])
                diff, kind = (p["difference"], p["low"], p["high"]), "paired"
            else:
                diff = tuple(aoc[k] - r["value"] for k in ("value", "low", "high"))
                kind = "against exact"
        r["aoc_minus"], r["aoc_minus_low"], r["aoc_minus_high"] = diff or (None, None, None)
        r["aoc_minus_kind"] = kind
        r["ahead"] = None if diff is None else reading(diff[1], diff[2])
    return rows


def reading(low: float, high: float) -> str:
    """What an interval of AOC's survival less a method's shows."""
    return "shown ahead" if low > 0 else "shown behind" if high < 0 else "not shown apart"


def summarise(rows: list[dict], methods: list[str]) -> list[dict]:
    """Per method, noise and size: the mean over seeds (and the mean interval)."""
    out = []
    cells = sorted({(r["noise"], r["stays"]) for r in rows})
    for noise, stays in cells:
        for method in methods:
            mine = [r for r in rows if (r["method"], r["noise"], r["stays"]) ==
                    (method, noise, stays)]
            done = [r for r in mine if r["status"] == "ok"]
            if not mine:
                continue
            rec = {"method": method, "sees": SEES[method], "stays": stays, "noise": noise,
                   "seeds": len(done), "value": None, "low": None, "high": None,
                   "kind": mine[0]["kind"], "status": "ok" if done else "skipped",
                   "note": "" if done else mine[0]["note"]}
            if done:
                rec.update({k: float(np.mean([r[k] for r in done]))
                            for k in ("value", "low", "high")})
            paired = [r for r in done if r.get("aoc_minus") is not None]
            rec.update({k: float(np.mean([r[k] for r in paired])) if paired else None
                        for k in DIFFERENCE})
            rec["aoc_minus_kind"] = paired[0]["aoc_minus_kind"] if paired else None
            rec["ahead"] = reading(rec["aoc_minus_low"], rec["aoc_minus_high"]) if paired \
                else None
            out.append(rec)
    return out


def markdown(summary: list[dict], episodes: int) -> str:
    lines = [f"Survival in the ICU-Sepsis MDP. Monte-Carlo: {episodes} episodes through the "
             "cohort's noise and gaps, the same episodes (rollout seed) for every method of a "
             "cell: paired. Exact: the state policy's value in the MDP. *told the state*: "
             "reads the true state, which the cohort never shows (an upper reference). "
             "*aoc minus it*: AOC's survival less the method's, with its 95% interval: over "
             "the same episodes for a rolled-out method (paired), AOC's own interval for an "
             "exact one.", "",
             "| method | sees | stays | noise | seeds | survival | 95% interval | kind "
             "| aoc minus it | 95% interval | reading |",
             "| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |"]
    for s in summary:
        if s["status"] != "ok":
            lines.append(f"| {s['method']} | {s['sees']} | {s['stays']} | {s['noise']:g} | 0 "
                         f"| skipped | {s['note']} | | | | |")
            continue
        interval = "" if s["kind"] == "exact" else f"{s['low']:.3f} - {s['high']:.3f}"
        diff = "| | | |" if s.get("aoc_minus") is None else (
            f"| {s['aoc_minus']:+.4f} | {s['aoc_minus_low']:+.3f} - {s['aoc_minus_high']:+.3f} "
            f"| {s['ahead']} ({s['aoc_minus_kind']}) |")
        lines.append(f"| {s['method']} | {s['sees']} | {s['stays']} | {s['noise']:g} | "
                     f"{s['seeds']} | {s['value']:.4f} | {interval} | {s['kind']} {diff}")
    return "\n".join(lines) + "\n"


def check(scale: str, seeds: int | None, methods: list[str], sizes: list[int] | None,
          noises: list[float] | None, episodes: int | None) -> None:
    """Bad scale, methods, seeds, sizes, noises or episodes -> AocError."""
    if scale not in SCALES:
        raise AocError(f"unknown scale {scale!r}: use {', '.join(SCALES)}")
    unknown = [m for m in methods if m not in METHODS]
    if unknown:
        raise BadSetting("methods", methods, f"{param('methods')}: unknown {', '.join(unknown)}; "
                         f"use {', '.join(METHODS)}")
    if seeds is not None and seeds < 1:
        raise BadSetting("seeds", seeds, f"{param('seeds')} must be >= 1, got {seeds}")
    if sizes is not None and (not sizes or any(s < 1 for s in sizes)):
        raise BadSetting("sizes", sizes, f"{param('sizes')}: stays per cohort must be >= 1, "
                         f"got {sizes}")
    if noises is not None and (not noises or any(
            not math.isfinite(v) or v < 0 for v in noises)):
        raise BadSetting("noise", noises, f"{param('noise')}: feature noise sds must be "
                         f"finite numbers >= 0, got {noises}")
    if episodes is not None and episodes < 1:
        raise BadSetting("episodes", episodes, f"{param('episodes')} (rollout episodes) must "
                         f"be >= 1, got {episodes}")


def run_cohort(out: Path, bench_store: Path, scale: str = "full", seeds: int | None = None,
               methods: list[str] | None = None, sizes: list[int] | None = None,
               noises: list[float] | None = None, episodes: int | None = None,
               threads: int | None = None, log=None, progress=None) -> dict:
    """Every size x noise x seed cohort, each method on it; write the outputs; the report
    ``{"summary", "rows", "out", "seconds"}``. ``threads``: AOC training's torch threads
    (None: ``aoc train``'s default); d3rlpy trains on one."""
    methods = list(methods or METHODS)
    check(scale, seeds, methods, sizes, noises, episodes)
    cfg = SCALES[scale]
    sizes = [int(s) for s in (sizes or cfg["sizes"])]
    noises = [float(v) for v in (noises if noises is not None else cfg["noises"])]
    n_seeds = int(seeds or 1)
    n_episodes = int(episodes or cfg["episodes"])
    started = time.perf_counter()
    store = Store(Path(bench_store))
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    rows: list[dict] = []
    cache: dict = {}
    cells = [(n, s, seed) for n in noises for s in sizes for seed in range(n_seeds)]
    for i, (noise, stays, seed) in enumerate(cells):
        if progress is not None:
            progress(i, len(cells), f"bench {TASK}: {stays} stays, noise {noise:g}, seed {seed}")
        rows += run_cell(store, stays, noise, seed, cfg, methods, n_episodes, threads, cache,
                         log)
    if progress is not None:
        progress(len(cells), len(cells), f"bench {TASK}")
    summary = summarise(rows, methods)
    write_rows_csv(out / "results.csv", rows)
    with atomic_path(out / "summary.json", suffix=".json") as tmp:
        Path(tmp).write_text(json.dumps({"task": TASK, "scale": scale, "sizes": sizes,
                                         "noises": noises, "seeds": n_seeds,
                                         "episodes": n_episodes, "summary": summary,
                                         "rows": rows}, indent=2))
    with atomic_path(out / "summary.md", suffix=".md") as tmp:
        Path(tmp).write_text(markdown(summary, n_episodes))
    return {"summary": summary, "rows": rows, "out": str(out),
            "seconds": time.perf_counter() - started}
