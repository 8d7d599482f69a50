"""How ABC's score should be computed from the named rows on ward (docs/notes/results-ward.md;
docs/design.md, "Row labels"), against a BC-MLP on the same splits, on any ward log.

    OMP_NUM_THREADS=1 .venv/bin/python benchmarks/notes/ward_row_labels.py --store DIR
        [--log-seed 0] [--splits 0,...,9]

For each of ``aoc bench ward``'s random 10:1 patient splits of the ward log collected with
``--log-seed`` (550 patients; the bench's is seed 0): the model trained exactly as the bench
trains it (reused when DIR already holds it; ward_candidates.py's splits and training), its
held-out steps and its training patients' validation episodes (decomposed over the other
training rows, as ``val_abc_*``) decomposed with the default candidates (63 rows of each
action), and each decision's score computed from the same minimal corpus subset with the
rows' labels l^c (aoc_cli/belief/row_labels.py) of each variant:

* ``logged``: the logged action (the paper's score, lambda 0);
* ``head:L``: the logged action smoothed by lambda L towards the belief's probability at the
  row (L = 0.25, 0.5, 0.75, 1);
* ``knn:M``: the mean logged action of the row's M nearest corpus rows in belief space
  (itself included; M = 5, 11, 21).

Prints per split, then per variant the held-out AUC (mean, worst split), accuracy (the
score's argmax) and the validation AUC, beside the BC-MLP (scikit-learn, as the bench's
``bc-mlp``) and the head. The rule that chose lambda: the best validation AUC pooled over
logs 0 and 1; of the variants within 0.001 of it, the smallest lambda.
"""

from __future__ import annotations

import json

import numpy as np
from scipy.spatial import cKDTree

from aoc_cli.belief import subset_scores
from aoc_cli.decompose import decompose, per_action_k
from aoc_cli.experiments import history_features
from aoc_cli.index import BeliefIndex, PerAction
from aoc_cli.threads import one_thread

from ward_candidates import split_beliefs, split_parser, store_and_log  # this folder's

VARIANTS = ["logged"] + [f"head:{x}" for x in (0.25, 0.5, 0.75, 1.0)] + \
           [f"knn:{m}" for m in (5, 11, 21)]


def scores(variant: str, rows, weights, b_corpus, a_corpus, head) -> np.ndarray:
    """(Q,) the treated action's score of each decision with the rows' labels of ``variant``."""
    kind, _, arg = variant.partition(":")
    if kind == "logged":
        return subset_scores(rows, weights, a_corpus, 2)[:, 1]
    if kind == "head":
        return subset_scores(rows, weights, a_corpus, 2, b_corpus, head, float(arg))[:, 1]
    _, near = cKDTree(b_corpus).query(b_corpus, k=int(arg))
    label = a_corpus[near].mean(1)
    used = rows >= 0
    return np.where(used, weights * label[np.maximum(rows, 0)], 0.0).sum(1)


def one_split(store, data, split: int) -> dict:
    from sklearn.metrics import roc_auc_score
    from sklearn.neural_network import MLPClassifier
    from sklearn.pipeline import make_pipeline
    from sklearn.preprocessing import StandardScaler

    tr, te, model, b_tr, b_te, a_tr, y, val = split_beliefs(store, data, split)
    L = model.history_length
    head = model.head_weights
    k = per_action_k(b_tr.shape[1], 2)
    with one_thread():
        test = decompose(b_tr, b_te, k=k, index=PerAction(
            BeliefIndex.build(b_tr.astype(np.float32), kind="flat"), a_tr))
        valid = decompose(b_tr[~val], b_tr[val], k=k, index=PerAction(
            BeliefIndex.build(b_tr[~val].astype(np.float32), kind="flat"), a_tr[~val]))
    x_tr = history_features(np.asarray(tr.observations, float), a_tr, tr.episode_starts, L)
    x_te = history_features(np.asarray(te.observations, float), y, te.episode_starts, L)
    mlp = make_pipeline(StandardScaler(), MLPClassifier(
        (128, 128), early_stopping=True, max_iter=500, random_state=split)).fit(x_tr, a_tr)
    p_mlp = mlp.predict_proba(x_te)[:, 1]
    z = b_te.astype(np.float64) @ head.weight.T + head.bias
    out = {"split": split, "history_length": L, "bc_mlp_auc": roc_auc_score(y, p_mlp),
           "bc_mlp_accuracy": float(np.mean((p_mlp >= 0.5) == y)),
           "head_auc": roc_auc_score(y, z[:, 1] - z[:, 0]),
           "subset_rows_max": int((test.rows >= 0).sum(1).max()), "variants": {}}
    for v in VARIANTS:
        s = scores(v, test.rows, test.weights, b_tr, a_tr, head)
        sv = scores(v, valid.rows, valid.weights, b_tr[~val], a_tr[~val], head)
        out["variants"][v] = {"auc": roc_auc_score(y, s), "accuracy": float(np.mean((s > .5) == y)),
                              "val_auc": roc_auc_score(a_tr[val], sv)}
    return out


def main() -> None:
    args = split_parser(__doc__).parse_args()
    store, data = store_and_log(args)
    results = []
    for split in (int(x) for x in args.splits.split(",")):
        results.append(one_split(store, data, split))
        print(json.dumps(results[-1]), flush=True)
    mlp = np.array([r["bc_mlp_auc"] for r in results])
    print(f"bc-mlp: AUC {mlp.mean():.4f} (worst {mlp.min():.4f}), accuracy "
          f"{np.mean([r['bc_mlp_accuracy'] for r in results]):.4f}; head AUC "
          f"{np.mean([r['head_auc'] for r in results]):.4f}; named rows at most "
          f"{max(r['subset_rows_max'] for r in results)}")
    for v in VARIANTS:
        auc = np.array([r["variants"][v]["auc"] for r in results])
        print(f"{v:10s} held-out AUC {auc.mean():.4f} (worst {auc.min():.4f}, split "
              f"{results[int(auc.argmin())]['split']}), accuracy "
              f"{np.mean([r['variants'][v]['accuracy'] for r in results]):.4f}; validation AUC "
              f"{np.mean([r['variants'][v]['val_auc'] for r in results]):.4f}")


if __name__ == "__main__":
    main()
