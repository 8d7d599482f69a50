"""How many rows of each action ABC's step 1 should take on ward (docs/notes/results-ward.md;
docs/design.md, "Candidates of every action"), and why a split scores low.

    OMP_NUM_THREADS=1 .venv/bin/python benchmarks/notes/ward_candidates.py --store DIR
        [--log-seed 0] [--splits 0,...,9] [--per 42,63,84,126,168]

For each of ``aoc bench ward``'s random 10:1 patient splits of the ward log collected with
``--log-seed`` (550 patients; the bench's is seed 0): the model trained exactly as the bench
trains it (``train_corpus``, settings chosen by validation; reused when DIR already holds it),
then its held-out steps and its training patients' validation episodes (the training's own
split: decomposed over the other training rows, as ``val_abc_*``) decomposed with each count
of rows per action in ``--per``; prints, per split and count, the AUC and accuracy of ABC's
scores (the treated rows' weight in the minimal corpus subset) on both, then the means and
the worst split. Also, for the record: the head's AUC on the query belief y and on its
projection y* (the residual is under 0.2% of |y|, so the two rank alike), and on the subset's
weights of its rows' head probabilities instead of their logged actions (the subset's own
geometry with the labels' noise taken out), and the mean of the subsets' scores over the
counts 42, 84 and 168 (a decision naming three subsets: measured, not adopted).
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

from aoc_cli.belief import load_model, split_episodes
from aoc_cli.training import abc_scores, train_corpus
from aoc_cli.decompose import decompose
from aoc_cli.envs import collect
from aoc_cli.index import BeliefIndex, PerAction
from aoc_cli.store import DEFAULT_MODEL, Store
from aoc_cli.threads import one_thread

PATIENTS = 550


def split_corpora(store: Store, data, split: int):
    """The bench's split ``split`` (aoc_cli/experiments/ward.py run_split): (train, test)."""
    rng = np.random.default_rng([0, split])
    test = np.zeros(PATIENTS, bool)
    test[rng.choice(PATIENTS, size=PATIENTS // 11, replace=False)] = True
    tr_name, te_name = f"ward-split{split}", f"ward-split{split}-test"
    if not (store.exists(tr_name) and store.exists(te_name)):
        store.write(tr_name, data.select_episodes(~test))
        store.write(te_name, data.select_episodes(test))
    return store.corpus(tr_name), store.corpus(te_name)


def split_beliefs(store: Store, data, split: int):
    """Split ``split``'s corpora, its ABC model (trained when missing, as the bench trains it)
    and what both scripts score: (train corpus, test corpus, model, b_tr (N, d_b), b_te
    (Q, d_b), a_tr (N,), y (Q,), val (N,) bool: the rows of the model's validation episodes)."""
    tr, te = split_corpora(store, data, split)
    if not (tr.models_dir / DEFAULT_MODEL).exists():
        train_corpus(tr, DEFAULT_MODEL, overwrite=True, mode="imitation", threads=1, seed=split)
    model = load_model(tr, DEFAULT_MODEL)
    cfg = json.loads((tr.models_dir / DEFAULT_MODEL / "config.json").read_text())["config"]
    L = model.history_length
    b_tr = model.beliefs(np.asarray(tr.observations), None, tr.history(np.arange(tr.n_rows), L))
    b_te = model.beliefs(np.asarray(te.observations), None, te.history(np.arange(te.n_rows), L))
    a_tr, y = np.asarray(tr.actions), np.asarray(te.actions)
    _, val_eps = split_episodes(tr.n_episodes, cfg["val_fraction"], cfg["seed"])
    val = np.isin(tr.episode_of(np.arange(tr.n_rows)), val_eps)
    return tr, te, model, b_tr, b_te, a_tr, y, val


def decomposed(b_corpus, a_corpus, queries, per: int):
    """(scores (Q, 2), decomposition) with ``per`` rows of each action as candidates."""
    search = PerAction(BeliefIndex.build(b_corpus.astype(np.float32), kind="flat"), a_corpus)
    dec = decompose(b_corpus, queries, k=2 * per, index=search)
    return abc_scores(dec.rows, dec.weights, a_corpus, 2), dec


def one_split(store, data, split: int, counts: list[int]) -> dict:
    from sklearn.metrics import roc_auc_score

    tr, te, model, b_tr, b_te, a_tr, y, val = split_beliefs(store, data, split)
    w, c = np.asarray(model.head_weights.weight), np.asarray(model.head_weights.bias)

    def logit(b):
        z = b.astype(np.float64) @ w.T + c
        return z[:, 1] - z[:, 0]

    out = {"split": split, "held_out_treated": int(y.sum()), "per": {}}
    scores = {}
    with one_thread():
        for per in sorted(set(counts) | {42, 84, 168}):
            s, dec = decomposed(b_tr, a_tr, b_te, per)
            scores[per] = s[:, 1]
            if per not in counts:
                continue
            sv, _ = decomposed(b_tr[~val], a_tr[~val], b_tr[val], per)
            out["per"][per] = {"auc": roc_auc_score(y, s[:, 1]),
                               "accuracy": float(np.mean(s.argmax(1) == y)),
                               "val_auc": roc_auc_score(a_tr[val], sv[:, 1]),
                               "val_accuracy": float(np.mean(sv.argmax(1) == a_tr[val])),
                               "subset_rows": float(np.mean((dec.rows >= 0).sum(1)))}
            if per == counts[0]:
                p_rows = 1.0 / (1.0 + np.exp(-logit(b_tr)))
                used = dec.rows >= 0
                soft = np.where(used, dec.weights * p_rows[np.maximum(dec.rows, 0)], 0).sum(1)
                out["head_auc"] = roc_auc_score(y, logit(b_te))
                out["head_auc_at_projection"] = roc_auc_score(y, logit(dec.projection))
                out["subset_of_head_probabilities_auc"] = roc_auc_score(y, soft)
                out["residual_over_norm"] = float(np.median(
                    dec.residual / np.linalg.norm(b_te, axis=1)))
    mean3 = (scores[42] + scores[84] + scores[168]) / 3
    out["three_subsets_auc"] = roc_auc_score(y, mean3)
    out["three_subsets_accuracy"] = float(np.mean((mean3 > 0.5) == y))
    return out


def split_parser(doc: str) -> argparse.ArgumentParser:
    """The ward notes' arguments: ``--store``, ``--log-seed`` (the ward log), ``--splits``."""
    ap = argparse.ArgumentParser(description=doc.split("\n\n")[0])
    ap.add_argument("--store", required=True)
    ap.add_argument("--log-seed", type=int, default=0)
    ap.add_argument("--splits", default=",".join(map(str, range(10))))
    return ap


def store_and_log(args) -> tuple[Store, object]:
    """The notes' store and the ward log of ``--log-seed`` (its CorpusData)."""
    data, _ = collect("ward", episodes=PATIENTS, seed=args.log_seed)
    return Store(Path(args.store)), data


def main() -> None:
    ap = split_parser(__doc__)
    ap.add_argument("--per", default="42,63,84,126,168")
    args = ap.parse_args()
    counts = [int(x) for x in args.per.split(",")]
    store, data = store_and_log(args)
    results = []
    for split in (int(x) for x in args.splits.split(",")):
        r = one_split(store, data, split, counts)
        results.append(r)
        print(json.dumps(r), flush=True)
    for per in counts:
        auc = np.array([r["per"][per]["auc"] for r in results])
        acc = np.array([r["per"][per]["accuracy"] for r in results])
        vauc = np.array([r["per"][per]["val_auc"] for r in results])
        print(f"{per} of each action: held-out AUC {auc.mean():.4f} (worst {auc.min():.4f}, "
              f"split {results[int(auc.argmin())]['split']}), accuracy {acc.mean():.4f}; "
              f"validation AUC {vauc.mean():.4f}")
    three = np.array([r["three_subsets_auc"] for r in results])
    print(f"mean of the 42 / 84 / 168 subsets: AUC {three.mean():.4f} (worst {three.min():.4f}),"
          f" accuracy {np.mean([r['three_subsets_accuracy'] for r in results]):.4f}")


if __name__ == "__main__":
    main()
