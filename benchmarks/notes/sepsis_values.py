"""Which row values would lift AOC on an icu-sepsis log (docs/notes/results-icu-sepsis.md): the
controller's decisions with other values v^c swapped into its index, valued exactly.

    OMP_NUM_THREADS=1 .venv/bin/python benchmarks/notes/sepsis_values.py --store DIR --corpus NAME
        [--variant NAME:KEY=VALUE,...] ... [--references]

For a corpus with a trained ``--value fqe`` model of history length 0 and its index (``aoc
train NAME``, ``aoc index NAME``): each ``--variant`` is fitted Q evaluation
(``aoc_cli.belief.fqe``) with FQEConfig fields changed (``ens=M``: the mean of M seeds; a
value is an int, a float or a word), e.g. ``h256:hidden=256``, ``ens3:ens=3``,
``l30:next_value=logged,iterations=30`` (the default before 2026-11-26); ``base`` is the stored
model's own values. For each: **validation from the log alone** (fitted on 70% of the episodes, the mean
squared error of Q(o, a) against the held-out 30%'s returns-to-go on the (state, dose) pairs
both hold: the behaviour's Q is their expectation, so a lower error is a better Q up to a
constant), then the values fitted on the whole log swapped into the index (the beliefs and
the decomposition unchanged: a logged pair decomposes to its own rows), every live state
decided with the task's controller and valued exactly; also the rows' mean |v - Q| against the
clinicians' exact Q (for the record, never for choosing). ``--references`` adds the count model
of the log told the state (``sepsis_policies.log_model``) and the exact Q as values.
"""

from __future__ import annotations

import argparse
import json
import time
from dataclasses import replace

import numpy as np

from aoc_cli.belief import FQEConfig, fitted_q_values
from aoc_cli.control import open_session
from aoc_cli.envs import sepsis_tables
from aoc_cli.experiments import log_model, state_policy
from aoc_cli.store import DEFAULT_MODEL, Store, model_dir
from aoc_cli.threads import one_thread

VAL_SHARE = 0.3


def _number(text: str):
    """A --variant value: an int, a float or a word (``next_value=expected``)."""
    for kind in (int, float):
        try:
            return kind(text)
        except ValueError:
            pass
    return text


def fqe(obs, act, rew, starts, spec: dict) -> np.ndarray:
    spec = dict(spec)
    ens = int(spec.pop("ens", 1))
    cfg = replace(FQEConfig(), **spec)
    return np.mean([fitted_q_values(obs, act, rew, starts, 1.0, 25, replace(cfg, seed=k))
                    for k in range(ens)], axis=0)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--store", required=True)
    ap.add_argument("--corpus", required=True)
    ap.add_argument("--model", default=DEFAULT_MODEL)
    ap.add_argument("--variant", action="append", default=[])
    ap.add_argument("--references", action="store_true")
    args = ap.parse_args()
    t = sepsis_tables("mean")
    corpus = Store(args.store).corpus(args.corpus)
    data = corpus.load()
    obs, rew, starts = data.observations, data.rewards, data.episode_starts
    act = np.asarray(data.actions, np.int64)
    s = data.columns["state"].astype(np.int64)
    n_ep = len(starts) - 1
    val = np.random.default_rng(0).random(n_ep) < VAL_SHARE
    ep = np.repeat(np.arange(n_ep), np.diff(starts))
    rtg = np.zeros(len(rew))
    for e in range(n_ep):
        a, b = starts[e], starts[e + 1]
        rtg[a:b] = np.cumsum(rew[a:b][::-1])[::-1]
    tr, va = ~val[ep], val[ep]
    tr_starts = np.concatenate([[0], np.cumsum(np.diff(starts)[~val])])
    seen = np.zeros((t.mdp.n_states, 25), bool)
    seen[s[tr], act[tr]] = True
    ok = seen[s[va], act[va]]
    q_exact = t.mdp.q_values(t.clinicians)
    stored = model_dir(corpus.path, args.model) / "values.npy"

    def by_pair(rows_q, rows):
        table = np.zeros((t.mdp.n_states, 25))
        table[s[rows], act[rows]] = rows_q
        return table

    def report(name, v, val_q=None, seconds=0.0):
        session = open_session(corpus, args.model)  # the model's own controller settings
        ctl = session.controller
        ctl.index.values = v
        ctl.value_std = float(np.std(v))
        with one_thread():
            pol = state_policy(ctl.decide, t, 0)
        mse = None if val_q is None else round(float(np.mean(
            (val_q[s[va], act[va]][ok] - rtg[va][ok]) ** 2)), 5)
        print(json.dumps({"values": name, "val_mse": mse,
                          "abs_err_rows": round(float(np.mean(np.abs(v - q_exact[s, act]))), 4),
                          "exact": round(t.mdp.value(pol), 4),
                          "fit_seconds": round(seconds, 1)}), flush=True)

    for text in args.variant:
        name, _, kv = text.partition(":")
        spec = {k: _number(x) for k, x in (p.split("=") for p in kv.split(",") if p)}
        started = time.perf_counter()
        val_q = by_pair(fqe(obs[tr], act[tr], rew[tr], tr_starts, spec), tr)
        v = np.load(stored) if name == "base" else fqe(obs, act, rew, starts, spec)
        report(name, v, val_q, time.perf_counter() - started)
    if args.references:
        model, behaviour, _counts = log_model(s[tr], act[tr], rew[tr], data.terminals[tr],
                                                 tr_starts)
        val_q = model.q_values(behaviour)
        model, behaviour, _counts = log_model(s, act, rew, data.terminals, starts)
        report("count model (told the state)", model.q_values(behaviour)[s, act], val_q)
        report("exact Q", q_exact[s, act], q_exact)


if __name__ == "__main__":
    main()
