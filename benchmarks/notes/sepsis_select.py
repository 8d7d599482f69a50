"""icu-sepsis from a plain file: the controller selection of ``aoc train``
(aoc_cli.training.controller_selection) against the truth. For a model trained by
``benchmarks/notes/sepsis_plain_file.py`` (its store), each candidate controller's FQE estimate
on the model's validation episodes (what the rule sees) beside its exact survival as a state
policy with the final index (what the user gets; read only here, never by the rule).
docs/notes/results-icu-sepsis.md, "From a user's plain file".

    python benchmarks/notes/sepsis_select.py --store /tmp/x [--task icu-sepsis]
"""

from __future__ import annotations

import argparse
import json

import numpy as np
import torch

import aoc_cli
from aoc_cli.control import ControllerConfig
from aoc_cli.envs import sepsis_tables
from aoc_cli.experiments import state_policy
from aoc_cli.store import Store

# the selection's own steps on a saved model (its network, encoded inputs and split), as
# internal: training hands them to the selection's hook
from aoc_cli.belief import load_model
from aoc_cli.belief.data import TrainingData, episode_rows, split_episodes
from aoc_cli.belief.inputs import encode_corpus
from aoc_cli.belief.model import Normalisation
import aoc_cli.training.controller_selection as controller_selection
from aoc_cli.training.evidence import label


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--store", required=True)
    ap.add_argument("--name", default="mine")
    ap.add_argument("--task", default="icu-sepsis")
    args = ap.parse_args()
    corpus = Store.open(args.store).corpus(args.name)
    model = load_model(corpus, None, device="cpu")
    config = model.config
    norm = Normalisation.from_dict(model.meta["normalisation"])
    inputs = encode_corpus(corpus, model.encoder, config.history_length, True,
                           torch.device("cpu"))
    train_eps, val_eps = split_episodes(corpus.n_episodes, config.val_fraction, config.seed)
    starts = np.asarray(corpus.episode_starts, np.int64)
    data = TrainingData(np.asarray(model.values, np.float64), train_eps, val_eps,
                        episode_rows(starts, train_eps), episode_rows(starts, val_eps))
    saved = model.meta["metrics"].get("controller") or {}
    k = int(saved.get("k") or 2 * (model.d_b + 1))
    out = controller_selection.select_controller(model.net, inputs, data, norm, corpus, config, k,
                                      controller_selection.candidates(saved.get("support_penalty")))
    t = sepsis_tables("terminate" if args.task.endswith("terminate") else "mean")
    for cand in out["candidates"]:
        session = aoc_cli.open_session(args.name, store=args.store,
                                       controller=ControllerConfig(**cand["settings"]))
        cand["exact"] = round(float(t.mdp.value(state_policy(session.controller.decide, t))), 4)
    print(json.dumps({"chosen": out["chosen"], "seconds": round(out["seconds"], 1),
                      "episodes": out["episodes"], "steps": out["steps"],
                      "candidates": [{**c, "settings": label(c["settings"])}
                                     for c in out["candidates"]],
                      "clinicians": round(float(t.mdp.value(t.clinicians)), 4)}))


if __name__ == "__main__":
    main()
