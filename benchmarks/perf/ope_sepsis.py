"""Offline policy evaluation on icu-sepsis against the exact values (issue 26): on held-out
logs of clinician episodes, does each estimator's 95% interval cover the truth, and how far is
its point estimate?

    OMP_NUM_THREADS=1 .venv/bin/python benchmarks/perf/ope_sepsis.py [--logs 10] [--episodes 5000]
        [--train-episodes 10000] [--store DIR] [--out results.json] [-f json]

Builds (once, in ``--store``) a corpus of ``--train-episodes`` clinician episodes, its value
model as ``aoc train NAME`` trains it with no flags (the task's own settings: fqe values,
gamma 1, history 0, so AOC's decision depends on the state alone) and its index (``aoc index
NAME``); a stored model trained with other settings is refused. AOC is the controller with the
task's settings (residual cap, support penalty), as ``aoc evaluate`` opens it
(``aoc_cli.open_session``). AOC's policy is its decision in every state: each state's
observation decided by ``aoc_cli.evaluation.score`` (one-step episodes, the same code path as
``aoc evaluate``); on the first held-out log the script checks that ``aoc evaluate``'s own
decisions are that policy's. BC is the training log's most frequent action per state (the
clinicians' modal action as the log shows it). The clinicians are the behaviour itself (the
package's stochastic policy). Truths: the package's tables by a linear solve
(``aoc_cli.envs.icu_sepsis.tables``). Then for each of ``--logs`` held-out logs of
``--episodes`` clinician episodes (seeds 1000, 1001, ...), the estimators of ``aoc evaluate``
(:mod:`aoc_cli.ope.evaluate_block`: PDWIS, WDR, FQE with the log's ``propensity`` column) for
each policy. Prints one row per policy and estimator: coverage (of the logs), mean estimate,
mean error, mean |error|, mean interval width, mean ESS.
"""

from __future__ import annotations

import json
import sys
import time
from pathlib import Path

import _harness as h

h.omp_threads(1)

import numpy as np  # noqa: E402

import aoc_cli  # noqa: E402
from aoc_cli.envs.icu_sepsis import tables  # noqa: E402
from aoc_cli.errors import AocError  # noqa: E402
from aoc_cli.evaluation.score import score_log  # noqa: E402
from aoc_cli.ope import estimators as ope  # noqa: E402
from aoc_cli.ope.fqe import REFITS, SCHEDULE  # noqa: E402
from aoc_cli.ope.evaluate_block import (  # noqa: E402  # noqa: E402
    ESTIMATORS,
    OPESettings,
    fqe_values,
    parse_estimators,
    policy_value,
)
from aoc_cli.store import DEFAULT_MODEL, CorpusData, Store, model_dir  # noqa: E402
from aoc_cli.threads import one_thread  # noqa: E402

#: The value model's settings ``aoc train NAME`` decides for an icu-sepsis log (its
#: observations recur: aoc_cli.training.evidence, rule 2).
TASK_VALUE = {"value": "fqe", "gamma": 1.0, "history_length": 0}


def prepare(store: Store, train_episodes: int):
    """The training corpus, its value model and index, as ``aoc collect``, ``aoc train NAME``
    and ``aoc index NAME`` build them with no flags (their API entries, on this store)."""
    corpus = h.corpus_ready(store, "train", "icu-sepsis", episodes=train_episodes, seed=0,
                            train=dict(seed=0), index={})
    config = model_dir(corpus.path, DEFAULT_MODEL) / "config.json"
    got = json.loads(config.read_text())["config"]
    if any(got[k] != v for k, v in TASK_VALUE.items()):
        raise AocError(f"the stored model of {store.root}/train was trained with "
                       f"{ {k: got[k] for k in TASK_VALUE} }, not the task's {TASK_VALUE}: "
                       "delete it (or use another --store)")
    return corpus


def aoc_policy(store: Store, corpus, t) -> np.ndarray:
    """(716,) AOC's decision in every state (terminal states: 0), by aoc's evaluate."""
    states = np.flatnonzero(~t.mdp.terminal)
    n = len(states)
    one = np.ones(n, bool)
    data = CorpusData(observations=t.observations[states].astype(np.float32),
                      actions=np.zeros(n, np.int64), rewards=np.zeros(n),
                      terminals=one, truncations=~one, episode_starts=np.arange(n + 1),
                      observation_space=corpus.observation_space,
                      action_space=corpus.action_space)
    try:
        every = store.corpus("every-state")
    except AocError:
        every = store.write("every-state", data)
    session = aoc_cli.open_session(corpus.name, store=store)  # the task's controller settings
    _, res = score_log(session, every, [], ope=OPESettings(estimators=()))
    policy = np.zeros(t.mdp.n_states, np.int64)
    policy[states] = res.decided
    return policy


def bc_policy(corpus, t) -> np.ndarray:
    """(716,) the training log's most frequent action per state (unseen: the overall mode)."""
    s = corpus.column("state").astype(np.int64)
    counts = np.zeros((t.mdp.n_states, corpus.n_actions))
    np.add.at(counts, (s, corpus.actions), 1)
    out = counts.argmax(1)
    out[counts.sum(1) == 0] = np.bincount(corpus.actions).argmax()
    return out


def table(runs: list, truth: dict) -> list[dict]:
    """One row per policy and estimator over the logs' runs: coverage, mean, bias, mean
    |error|, mean width, mean ESS (``fqe_fit``: one fit's value inside FQE's interval)."""
    rows = []
    for pname in dict.fromkeys(x["policy"] for x in runs):
        for est in ("pdwis", "wdr", "fqe", "fqe_fit"):
            r = [x for x in runs if x["policy"] == pname and est in x
                 and (est == "fqe_fit" or x[est].get("estimate") is not None)]  # shown only
            if est == "fqe_fit":        # one fit's value as the point, FQE's interval around it
                half = [(x["fqe"]["high"] - x["fqe"]["low"]) / 2 for x in r]
                r = [{**x, est: {"estimate": x[est], "low": x[est] - h, "high": x[est] + h}}
                     for x, h in zip(r, half)]
            if not r:
                continue
            e = np.array([x[est]["estimate"] for x in r])
            cover = sum(x[est]["low"] <= x["truth"] <= x[est]["high"] for x in r)
            width = np.mean([x[est]["high"] - x[est]["low"] for x in r])
            rows.append({"policy": pname, "truth": round(truth[pname], 4), "estimator": est,
                         "covered": f"{cover} of {len(r)}", "mean": round(float(e.mean()), 4),
                         "bias": round(float(e.mean() - truth[pname]), 4),
                         "mean_abs_error": round(float(np.abs(e - truth[pname]).mean()), 4),
                         "width": round(float(width), 4),
                         "ess": round(float(np.mean([x["ess"] for x in r])), 1)})
    return rows


def main() -> None:
    ap = h.parser(__doc__)
    ap.add_argument("--logs", type=int, default=10)
    ap.add_argument("--first", type=int, default=0,
                    help="the first held-out log (logs FIRST .. FIRST + LOGS - 1): a run split "
                         "over processes, then --merge")
    ap.add_argument("--merge", nargs="+", default=None, metavar="JSON",
                    help="only print the table of these runs' --out files together")
    ap.add_argument("--episodes", type=int, default=5000)
    ap.add_argument("--train-episodes", type=int, default=10000)
    ap.add_argument("--store", default="/tmp/aoc-ope-sepsis")
    ap.add_argument("--fqe-steps", type=int, default=None)
    ap.add_argument("--fqe-refits", type=int, default=REFITS,
                    help="refits behind FQE's interval (0: one fit, start values resampled)")
    ap.add_argument("--estimators", default=",".join(ESTIMATORS))
    ap.add_argument("--fqe-schedule", default=SCHEDULE, choices=["constant", "cosine"],
                    help="FQE's learning rate over the fit and each refit")
    ap.add_argument("--out", default=None)
    ap.add_argument("--no-check", dest="check", action="store_false",
                    help="skip checking aoc evaluate's decisions on the first log")
    args = ap.parse_args()
    if args.merge:
        parts = [json.loads(Path(f).read_text()) for f in args.merge]
        runs = sorted((r for p in parts for r in p["runs"]), key=lambda r: r["log"])
        h.emit(table(runs, parts[0]["truth"]), args.format)
        return
    store = Store(args.store)
    t = tables("mean")
    corpus = prepare(store, args.train_episodes)
    policies = {"aoc": aoc_policy(store, corpus, t), "bc": bc_policy(corpus, t)}
    truth = {name: t.mdp.value(p) for name, p in policies.items()}
    truth["clinicians"] = t.mdp.value(t.clinicians)
    print("truth", json.dumps(truth), file=sys.stderr)
    settings = OPESettings(estimators=parse_estimators(args.estimators),
                           fqe_steps=args.fqe_steps, fqe_refits=args.fqe_refits,
                           fqe_schedule=args.fqe_schedule)
    runs = []
    for i in range(args.first, args.first + args.logs):
        started = time.perf_counter()
        name = f"held{i}"
        held = h.corpus_ready(store, name, "icu-sepsis", episodes=args.episodes, seed=1000 + i)
        s = held.column("state").astype(np.int64)
        logged = np.asarray(held.actions, np.int64)
        log = ope.Log(held.episode_starts, held.rewards, 1.0)
        prop = held.column("propensity")
        if i == args.first and args.check:   # aoc evaluate's own decisions are the policy evaluated here
            session = aoc_cli.open_session(corpus.name, store=store)
            _, res = score_log(session, held, [], ope=OPESettings(estimators=()))
            agree = float(np.mean(res.decided == policies["aoc"][s]))
            print(f"aoc evaluate's decisions = the state policy on {agree:.4f} of the steps",
                  file=sys.stderr)
        at_steps = {"aoc": policies["aoc"][s], "bc": policies["bc"][s],
                    "clinicians": t.clinicians[s]}
        probs = {k: (np.eye(held.n_actions)[p] if p.ndim == 1 else p)
                 for k, p in at_steps.items()}
        with one_thread():       # every policy's FQE in one ensemble, as aoc evaluate does
            fqes = fqe_values(log, held.observations, logged, list(probs.values()), settings,
                              propensity=prop)
        mean_return = float(log.returns().mean())
        for (pname, pol), fqe in zip(probs.items(), fqes):
            with one_thread():
                rec = policy_value(log, held.observations, logged, prop, pol, held.n_actions,
                                   settings, fqe=fqe)
            extra = {}
            if fqe is not None and len(fqe.get("replicates", ())) > 1:
                extra = {"fqe_fit": fqe["fit_estimate"], "fqe_seconds": fqe["seconds"],
                         "fqe_replicates": list(fqe["replicates"])}
            runs.append({"log": i, "policy": pname, "truth": truth[pname], "ess": rec["ess"],
                         "mean_return": mean_return, "notes": rec["notes"],
                         **rec["policy_value"], **extra})
        print(f"log {i}: {time.perf_counter() - started:.0f} s", file=sys.stderr)
        if args.out:
            Path(args.out).write_text(json.dumps({"truth": truth, "runs": runs}, indent=1))
    h.emit(table(runs, truth), args.format)


if __name__ == "__main__":
    main()
