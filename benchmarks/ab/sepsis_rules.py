"""AOC's decision rules on an icu-sepsis corpus, valued exactly: which part of the rule (the
residual filter, the residual cap, the support penalty) does what (docs/notes/results-icu-sepsis.md,
"icu-sepsis").

    OMP_NUM_THREADS=1 .venv/bin/python benchmarks/ab/sepsis_rules.py --store DIR --corpus NAME
        [--task icu-sepsis|icu-sepsis-terminate] [--model default]

For a corpus with a trained value model of history length 0 and its index (as ``aoc bench
icu-sepsis`` leaves them in its ``--bench-store``), decides every live state's observation once
under each rule and values that state policy exactly over the package's tables
(``aoc_cli.envs.icu_sepsis.tables``). Rules: the model's (``ControllerConfig.for_model``), the
paper's (epsilon 0.5, no cap, no support rule), the cap without the penalty, the penalty
without the cap. Prints one JSON row per rule: exact value, the share of live states where the
dose is inadmissible and the expected inadmissible decisions per patient (under
``terminate``: the probability of dying of one), the share of decisions on a (state, dose)
the corpus holds, the median support (distinct episodes behind v_hat), and of the
inadmissible decisions: the share on a logged (state, dose), its median count of logged rows,
and their mean v_hat (against the admissible decisions').
"""

from __future__ import annotations

import argparse
import json
import time

import numpy as np

from aoc_cli.control import ControllerConfig, model_controller, open_session
from aoc_cli.envs.icu_sepsis import STRATEGIES, tables
from aoc_cli.baselines import sepsis_policies as sp
from aoc_cli.store import DEFAULT_MODEL, Store
from aoc_cli.threads import one_thread


def rules(saved: dict) -> dict:
    """The model's own settings (``saved``: decided by ``aoc train``), the paper's, and each
    of the model's two rules alone."""
    own = ControllerConfig.for_model(saved)
    return {"model": own,
            "paper": ControllerConfig(),
            "cap, no penalty": ControllerConfig.for_model(saved, support_penalty=0.0),
            "penalty, no cap": ControllerConfig(support_penalty=own.support_penalty)}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--store", required=True)
    ap.add_argument("--corpus", required=True)
    ap.add_argument("--task", default="icu-sepsis", choices=sorted(STRATEGIES))
    ap.add_argument("--model", default=DEFAULT_MODEL)
    args = ap.parse_args()
    t = tables(STRATEGIES[args.task])
    corpus = Store(args.store).corpus(args.corpus)
    s = corpus.column("state").astype(np.int64)
    counts = np.zeros((t.mdp.n_states, corpus.n_actions), np.int64)
    np.add.at(counts, (s, np.asarray(corpus.actions, np.int64)), 1)
    logged = counts > 0
    live = np.arange(sp.LIVE)
    saved = model_controller(open_session(corpus, args.model).model)
    for name, config in rules(saved).items():
        started = time.perf_counter()
        session = open_session(corpus, args.model, config=config)
        decisions = []

        def keep(observation, history, _decide=session.controller.decide):
            out = _decide(observation, history)
            decisions.append(out)
            return out

        with one_thread():
            pol = sp.state_policy(keep, t, session.history_length)
        support = [d.support for d in decisions if getattr(d, "support", None) is not None]
        bad = ~t.admissible[live, pol[:sp.LIVE]]                             # (713,)
        v_hat = np.array([np.nan if d.value is None else d.value for d in decisions])
        chosen_rows = counts[live, pol[:sp.LIVE]]
        print(json.dumps({
            "rule": name, "value": round(t.mdp.value(pol), 4),
            **{k: round(v, 4) for k, v in sp.inadmissible(t, pol).items()},
            "logged_pair": round(float(np.mean(logged[np.arange(sp.LIVE), pol[:sp.LIVE]])), 4),
            "support_median": float(np.median(support)) if support else None,
            # the inadmissible decisions: on a logged pair? how many rows? their v_hat
            "inadmissible_logged": round(float(np.mean(logged[live, pol[:sp.LIVE]][bad])), 4)
            if bad.any() else None,
            "inadmissible_rows_median": float(np.median(chosen_rows[bad])) if bad.any() else None,
            "inadmissible_v_hat_mean": round(float(np.nanmean(v_hat[bad])), 4)
            if bad.any() else None,
            "admissible_v_hat_mean": round(float(np.nanmean(v_hat[~bad])), 4),
            "seconds": round(time.perf_counter() - started, 1)}), flush=True)


if __name__ == "__main__":
    main()
