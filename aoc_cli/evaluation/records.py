"""The per-step records of an evaluation (``aoc evaluate --steps FILE.jsonl``): one JSON-ready
record per scored step, with its supporting rows and their episodes."""

from __future__ import annotations

import numpy as np

from aoc_cli.control.records import episode_ids, label_of
from aoc_cli.evaluation.step_scores import StepScores
from aoc_cli.store import action_labels


def step_records(ctx_or_session, data, res: StepScores):
    """One JSON-ready record per scored step (for ``--steps FILE.jsonl``): episode, its id,
    step, logged action, decision (with their labels, ``logged_label`` / ``decision_label``,
    when the corpus's actions are labelled), scores, residual, warning, supporting rows with
    their episodes and ids."""
    corpus = ctx_or_session.corpus
    data_ids, corpus_ids = episode_ids(data), episode_ids(corpus)
    labels = action_labels(corpus.action_space)
    sup_ep = corpus.episode_of(np.maximum(res.support_rows, 0))
    for i in range(len(res.row)):
        keep = res.support_rows[i] >= 0
        rec = {"episode": int(res.episode[i]),
               "episode_id": None if data_ids is None else data_ids[res.episode[i]],
               "step": int(res.step[i]), "row": int(res.row[i]),
               "logged": np.asarray(res.logged[i]).tolist(),
               **label_of(labels, res.logged[i], "logged_label"),
               "decision": np.asarray(res.decided[i]).tolist(),
               **label_of(labels, res.decided[i], "decision_label")}
        if res.scores is not None:
            rec["scores"] = res.scores[i].tolist()
        if res.v_hat is not None:
            rec["v_hat"] = float(res.v_hat[i])
            rec["target"] = float(res.target[i])
        rec["residual"] = float(res.residual[i])
        rec["warning"] = bool(res.warning[i])
        rec["support"] = [{"row": int(r), "episode": int(e),
                           "episode_id": None if corpus_ids is None else corpus_ids[e],
                           "weight": float(w)}
                          for r, e, w in zip(res.support_rows[i][keep], sup_ep[i][keep],
                                             res.support_weights[i][keep])]
        for name, b in res.baselines.items():
            rec[f"{name}_decision"] = np.asarray(b["decided"][i]).tolist()
            rec.update(label_of(labels, b["decided"][i], f"{name}_decision_label"))
        yield rec
