"""Belief-model benchmark (issue 4): time to train on pendulum-het to early stop, and the four
pendulum-het figures (does the history identify the dynamics?).

    .venv/bin/python benchmarks/perf/train.py time    [--rows 100000] [--repeats 3] [--threads 2]
                                                     [-f json]
    .venv/bin/python benchmarks/perf/train.py figures [--rows 100000] [--seed 0] [--threads 2]
    .venv/bin/python benchmarks/perf/train.py devices --store DIR --corpus NAME [--paper]
                                                     [--devices cpu,cuda] [--repeats 1]

``time``: collect ``--rows`` pendulum-het rows (collect seed = run index), store them, and train
the default value-mode model (L = 4, d_b = 20, batch 500, Adam 1e-3, patience 10) to early stop
through the API (``aoc_cli.train(..., paper=True)``, as ``aoc train --paper``); reported: the
median and every run's wall seconds, CPU seconds of the process (all threads; on a machine
shared with other work the wall time grows, the CPU time much less), epochs and validation
R^2. Goal: <= 120 s for 100k rows on this machine.

``figures``: one corpus (collect seed ``--seed``), the default model with L = 4 and the same
model with L = 0; reports the validation R^2 of each, and the accuracy of a logistic probe that
predicts the ``system`` tag (normal / converse) of the validation episodes' rows, fitted on the
training episodes' rows, from the L = 4 beliefs, the L = 0 beliefs, and the raw (o, a).
Diagnostics beside the four figures: the same value models given the true system as a fourth
observation (how much the value depends on the system at all), and the probe on the beliefs of
an imitation-mode model (L = 4), whose target, the action, does depend on the system.

``devices``: the model of stored corpus ``--corpus`` (as ``aoc train NAME``, or ``--paper``)
trained on each of ``--devices`` (default: the CPU, and the GPU when torch sees one), the
devices interleaved over ``--repeats`` rounds; reported: the wall and CPU seconds of the whole
training (value targets included: fitted Q evaluation runs on the CPU), the belief fit's own
seconds, epochs and validation R^2 (other devices round otherwise: close, not equal). Then each
model is loaded as a machine without a GPU loads it (on the CPU) and on its own device: the
largest difference of the corpus's row beliefs between the two (``cross_device_max_diff``).
"""

from __future__ import annotations

import json
import sys
import tempfile

import _harness as h
import numpy as np

import aoc_cli
from aoc_cli.belief import episode_rows, load_model, logistic_probe, split_episodes
from aoc_cli.belief.inputs import pick_device
from aoc_cli.belief.config import BeliefConfig
from aoc_cli.store import Store, box_space


def pendulum_corpus(store: Store, name: str, rows: int, seed: int):
    return aoc_cli.collect("pendulum-het", name, store=store, steps=rows, seed=seed).corpus


def run_time(args) -> None:
    runs, epochs, r2 = h.Runs(), [], []
    with tempfile.TemporaryDirectory() as tmp:
        store = Store(tmp)
        for seed in range(args.repeats):
            name = pendulum_corpus(store, f"p{seed}", args.rows, seed).name
            # the paper's settings (BeliefConfig's defaults), as `aoc train --paper`
            m, wall, cpu = h.timed(lambda: aoc_cli.train(name, store=store, paper=True,
                                                         threads=args.threads).metrics)
            runs.add(wall, cpu, m)
            epochs.append(m["epochs"])
            r2.append(m["val_r2"])
            print(json.dumps({"seconds": wall, "cpu_seconds": cpu, "epochs": m["epochs"],
                              "best_epoch": m["best_epoch"], "val_r2": m["val_r2"]}),
                  file=sys.stderr, flush=True)
    h.emit([h.row("train to early stop", args.rows, runs, epochs=epochs, val_r2=r2,
                  s_per_epoch=[round(w / e, 2) for w, e in zip(runs.wall, epochs)])],
           args.format)


def system_probe(corpus, features: np.ndarray, config: BeliefConfig) -> float:
    """Probe accuracy on the validation episodes of ``config``'s split."""
    train_eps, val_eps = split_episodes(corpus.n_episodes, config.val_fraction, config.seed)
    tr = episode_rows(corpus.episode_starts, train_eps)
    va = episode_rows(corpus.episode_starts, val_eps)
    system = corpus.tag("system")[0]
    return logistic_probe(features[tr], system[tr], features[va], system[va])


def run_figures(args) -> None:
    with tempfile.TemporaryDirectory() as tmp:
        store = Store(tmp)
        corpus = pendulum_corpus(store, "p", args.rows, args.seed)

        def train(name: str, model: str, **settings) -> dict:  # the paper's settings but these
            return aoc_cli.train(name, store=store, model=model, paper=True,
                                 threads=args.threads, overwrite=True, **settings).metrics

        out = {"rows": corpus.n_rows, "episodes": corpus.n_episodes}
        for L in (4, 0):
            config = BeliefConfig(history_length=L, threads=args.threads)
            m, seconds, _ = h.timed(lambda: train("p", f"L{L}", history_length=L))
            beliefs = load_model(corpus, f"L{L}").row_beliefs(corpus)
            out[f"L{L}"] = {"val_r2": m["val_r2"], "epochs": m["epochs"],
                            "seconds": seconds,
                            "probe_beliefs": system_probe(corpus, beliefs, config)}
            print(json.dumps({f"L{L}": out[f"L{L}"]}), flush=True)
        oa = np.concatenate([corpus.observations, corpus.actions], axis=1)
        out["probe_observation_action"] = system_probe(corpus, oa, BeliefConfig())
        system = corpus.tag("system")[0]
        _, val_eps = split_episodes(corpus.n_episodes, 0.2, 0)
        va = episode_rows(corpus.episode_starts, val_eps)
        out["probe_chance"] = float(max(system[va].mean(), 1 - system[va].mean()))
        print(json.dumps({k: out[k] for k in ("probe_observation_action", "probe_chance")}),
              flush=True)
        # Diagnostic 1: does the value depend on the system? Give the model the true system.
        data = corpus.load()
        data.observations = np.concatenate(
            [data.observations, system[:, None].astype(np.float32)], axis=1)
        data.observation_space = box_space(4)
        store.write("oracle", data)
        for L in (4, 0):
            m = train("oracle", "o", history_length=L)
            out[f"L{L}_with_true_system"] = {"val_r2": m["val_r2"], "epochs": m["epochs"]}
            print(json.dumps({f"L{L}_with_true_system": out[f"L{L}_with_true_system"]}),
                  flush=True)
        # Diagnostic 2: imitation-mode beliefs (the action depends on the system).
        config = BeliefConfig(mode="imitation", threads=args.threads)
        m = train("p", "imitation", mode="imitation")
        beliefs = load_model(corpus, "imitation").row_beliefs(corpus)
        out["imitation_L4"] = {"val_r2": m["val_r2"], "epochs": m["epochs"],
                               "probe_beliefs": system_probe(corpus, beliefs, config)}
        print(json.dumps(out, indent=2))


def run_devices(args) -> None:
    import torch

    store = Store(args.store)
    corpus = store.corpus(args.corpus)
    devices = (args.devices.split(",") if args.devices else
               ["cpu"] + (["cuda"] if torch.cuda.is_available() else []))

    def train_on(device: str):
        return lambda _i: aoc_cli.train(args.corpus, store=store, model=f"on-{device}",
                                        device=device, threads=args.threads, paper=args.paper,
                                        overwrite=True).metrics

    runs = h.interleave({d: train_on(d) for d in devices}, args.repeats)
    rows = []
    for d in devices:
        beliefs = {where: load_model(corpus, f"on-{d}", device=where).row_beliefs(corpus)
                   for where in dict.fromkeys(["cpu", pick_device(d).type])}
        diff = float(np.abs(beliefs["cpu"] - beliefs[pick_device(d).type]).max())
        ms = runs[d].outs
        rows.append(h.row(f"train on {d}", corpus.n_rows, runs[d],
                          device=torch.cuda.get_device_name() if d == "cuda" else "cpu",
                          fit_s=[round(m["seconds"], 2) for m in ms],
                          epochs=[m["epochs"] for m in ms],
                          val_r2=[round(m["val_r2"], 4) for m in ms],
                          cross_device_max_diff=diff))
    h.emit(rows, args.format)


def main() -> None:
    ap = h.parser(__doc__, repeats=3)
    ap.add_argument("what", choices=["time", "figures", "devices"])
    ap.add_argument("--store", help="devices: the store holding --corpus")
    ap.add_argument("--corpus", help="devices: the corpus to train")
    ap.add_argument("--devices", default=None, help="devices: comma-separated, e.g. cpu,cuda")
    ap.add_argument("--paper", action="store_true", help="devices: the paper's settings")
    ap.add_argument("--rows", type=int, default=100_000)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--threads", type=int, default=2)
    args = ap.parse_args()
    {"time": run_time, "figures": run_figures, "devices": run_devices}[args.what](args)


if __name__ == "__main__":
    main()
