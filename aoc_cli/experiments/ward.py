"""`aoc bench ward`: the paper's strictly batch imitation case on the simulated ward.

Over random 10:1 splits by patient of one ward log, on the held-out patients' steps:

* **abc** -- ABC as a user gets it: ``aoc train --mode imitation`` with its default settings
  (chosen by validation, aoc_cli.training.tuning), ``aoc index``, ``aoc evaluate`` (the AUC score
  of oxygen is the sum over the minimal corpus subset of weight x each row's label of it,
  aoc_cli.belief.row_labels; the decision is the argmax of the scores);
* **abc-head** -- the same model's own head (the black box ABC explains);
* **bc-lr**, **bc-mlp** -- scikit-learn's logistic regression and MLP (128, 128; early stopping)
  on the same information ABC reads: the standardised observation and the previous L steps'
  observations and actions (L = the history length ABC's selection chose, zero-padded with a
  mask at the stay's start);
* **knn** -- the k = d_b + 1 nearest training rows on the standardised observation;
* **majority** -- the training log's most common action (AUC 0.5).

The log (``source``): ``ward``, the simulated ward task (:mod:`aoc_cli.envs.ward`), or ``medkit``,
stays drawn from medkit-learn's ward simulator, learned from real ward data as in the paper
(:mod:`aoc_cli.envs.medkit_ward`; the optional ``medkit`` extra). Its oxygen action is rarer (about
1% of steps), so its scales hold more patients.

Writes ``results.csv`` (one row per method x split), ``summary.json``, ``summary.md`` (mean and
std over splits) and ``ward.png`` (accuracy and AUC with their spread) to ``out``.
"""

from __future__ import annotations

import json
import time
from pathlib import Path

import numpy as np

from aoc_cli.training.fit import train_corpus
from aoc_cli.control import ControllerConfig, open_session
from aoc_cli.index import build_index
from aoc_cli.envs import collect, medkit_ward, render
from aoc_cli.errors import BadSetting, param
from aoc_cli.evaluation.score import score_log
from aoc_cli.experiments.results import write_rows_csv
from aoc_cli.store import DEFAULT_MODEL, Store, atomic_path

SCALES = {"full": {"patients": 550, "splits": 10}, "quick": {"patients": 550, "splits": 3},
          "tiny": {"patients": 110, "splits": 2}}
#: The medkit log's scales: about 1% of its steps are treated, so 2,000 patients (~17,700
#: rows, within the small-log rules) give ~18 treated held-out steps a split.
MEDKIT_SCALES = {"full": {"patients": 2000, "splits": 10},
                 "quick": {"patients": 2000, "splits": 3},
                 "tiny": {"patients": 440, "splits": 2}}
SOURCES = ("ward", "medkit")
METHODS = ("abc", "abc-head", "bc-lr", "bc-mlp", "knn", "majority")


def history_features(obs: np.ndarray, actions: np.ndarray, starts: np.ndarray,
                     length: int) -> np.ndarray:
    """(N, d_o + L (d_o + 2)) the observation, then the previous L steps' observation, action
    and a present-mask, oldest first, zero where before the episode's start."""
    n = len(obs)
    ep = np.searchsorted(starts, np.arange(n), side="right") - 1
    parts = [obs]
    for lag in range(length, 0, -1):
        prev = np.arange(n) - lag
        ok = prev >= starts[ep]
        safe = np.maximum(prev, 0)
        parts += [obs[safe] * ok[:, None], (actions[safe] * ok)[:, None], ok[:, None]]
    return np.concatenate(parts, axis=1).astype(np.float64)


def _sk_scores(model, x_tr, y_tr, x_te):
    from sklearn.pipeline import make_pipeline
    from sklearn.preprocessing import StandardScaler

    pipe = make_pipeline(StandardScaler(), model).fit(x_tr, y_tr)
    return pipe.predict_proba(x_te)[:, 1]


def source_log(source: str, patients: int, seed: int = 0):
    """The log of ``patients`` stays from ``source`` (see the module docstring)."""
    if source == "ward":
        return collect("ward", episodes=patients, seed=seed)[0]
    if source == "medkit":
        return medkit_ward.collect_data(patients, seed)
    raise BadSetting("source", source, f"{param('source')} {source!r} is unknown: use "
                     + " or ".join(SOURCES))


def run_split(store, data, split: int, patients: int, seed: int = 0,
              name: str = "ward") -> list[dict]:
    """One random 10:1 split by patient: every method's accuracy and AUC on the held-out
    steps (corpora ``NAME-splitS`` and ``NAME-splitS-test`` in ``store``)."""
    from sklearn.linear_model import LogisticRegression
    from sklearn.metrics import roc_auc_score
    from sklearn.neural_network import MLPClassifier

    rng = np.random.default_rng([seed, split])
    test = np.zeros(patients, bool)
    test[rng.choice(patients, size=patients // 11, replace=False)] = True
    tr_name, te_name = f"{name}-split{split}", f"{name}-split{split}-test"
    store.write(tr_name, data.select_episodes(~test), overwrite=True)
    store.write(te_name, data.select_episodes(test), overwrite=True)
    tr, te = store.corpus(tr_name), store.corpus(te_name)
    started = time.perf_counter()  # as `aoc train --mode imitation` trains (training/fit.py)
    metrics = train_corpus(tr, DEFAULT_MODEL, overwrite=True, mode="imitation", threads=1,
                           seed=split).metrics
    build_index(tr, DEFAULT_MODEL)
    session = open_session(tr, DEFAULT_MODEL, config=ControllerConfig())
    summary, _res = score_log(session, te, ["knn", "bc"])
    abc_seconds = time.perf_counter() - started
    chosen = metrics["selection"]["chosen"]
    rows = [{"method": "abc", "accuracy": summary["accuracy"], "auc": summary["auc"],
             "support_max": summary["support_max"], "k": summary["k"],
             "val_abc_auc": metrics.get("val_abc_auc"), "seconds": abc_seconds, **chosen}]
    for name, key in (("abc-head", "bc"), ("knn", "knn")):
        b = summary["baselines"][key]
        rows.append({"method": name, "accuracy": b["accuracy"], "auc": b["auc"]})
    y_tr, y_te = np.asarray(tr.actions), np.asarray(te.actions)
    L = int(chosen["history_length"])
    x_tr = history_features(np.asarray(tr.observations, float), y_tr, tr.episode_starts, L)
    x_te = history_features(np.asarray(te.observations, float), y_te, te.episode_starts, L)
    for name, model in (("bc-lr", LogisticRegression(max_iter=5000)),
                        ("bc-mlp", MLPClassifier((128, 128), early_stopping=True,
                                                 max_iter=500, random_state=split))):
        p = _sk_scores(model, x_tr, y_tr, x_te)
        rows.append({"method": name, "accuracy": float(np.mean((p >= 0.5) == y_te)),
                     "auc": float(roc_auc_score(y_te, p)) if len(set(y_te)) > 1 else None})
    majority = int(np.bincount(y_tr).argmax())
    rows.append({"method": "majority", "accuracy": float(np.mean(y_te == majority)),
                 "auc": 0.5 if len(set(y_te)) > 1 else None})
    for r in rows:
        r.update(split=split, train_rows=tr.n_rows, test_rows=te.n_rows)
    return rows


def summarise(rows: list[dict]) -> list[dict]:
    """Mean and std over splits per method; the AUC over the splits that have one (a
    held-out split with a single action has none: ``auc_splits`` counts those that do)."""
    out = []
    for m in METHODS:
        acc = np.array([r["accuracy"] for r in rows if r["method"] == m])
        auc = np.array([r["auc"] for r in rows if r["method"] == m and r["auc"] is not None])
        if len(acc):
            out.append({"method": m, "splits": int(len(acc)), "accuracy_mean": float(acc.mean()),
                        "accuracy_std": float(acc.std()),
                        "auc_mean": float(auc.mean()) if len(auc) else None,
                        "auc_std": float(auc.std()) if len(auc) else None,
                        "auc_splits": int(len(auc))})
    return out


def plot(summary: list[dict], out_png: Path) -> None:
    fig, ax = render.new_axes("ward: held-out patients (mean ± std over splits)", "method",
                              "score", size=(7.0, 4.0))
    x = np.arange(len(summary))
    for off, key, label in ((-0.18, "accuracy", "accuracy"), (0.18, "auc", "AUC")):
        nan = float("nan")
        ax.errorbar(x + off, [nan if s[f"{key}_mean"] is None else s[f"{key}_mean"]
                              for s in summary],
                    yerr=[nan if s[f"{key}_std"] is None else s[f"{key}_std"] for s in summary],
                    fmt="o", capsize=3, label=label)
    ax.set_xticks(x)
    ax.set_xticklabels([s["method"] for s in summary])
    ax.set_ylim(0.45, 1.0)
    ax.legend(loc="lower left")
    render.save(fig, out_png)


def run_ward(out: Path, bench_store: Path, scale: str = "full", splits: int | None = None,
             log=None, progress=None, source: str = "ward", patients: int | None = None) -> dict:
    """Collect the log (``source``) of ``patients`` stays (default: the scale's), run every
    split, write the outputs; the report. ``results.csv`` is rewritten (atomically) as each
    split ends, so a run stopped part way keeps the splits it finished."""
    if source not in SOURCES:
        source_log(source, 1)  # the one-line error
    cfg = (MEDKIT_SCALES if source == "medkit" else SCALES)[scale]
    n_splits = splits or cfg["splits"]
    patients = patients or cfg["patients"]
    started = time.perf_counter()
    store = Store(Path(bench_store))
    data = source_log(source, patients)
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    rows: list[dict] = []
    if progress is not None:
        progress(0, n_splits, "bench ward")
    for s in range(n_splits):
        rows += run_split(store, data, s, patients, name=source)
        write_rows_csv(out / "results.csv", rows)  # each split's rows kept as it ends
        if progress is not None:
            progress(s + 1, n_splits, "bench ward")
        if log is not None:
            abc = next(r for r in rows if r["method"] == "abc" and r["split"] == s)
            auc = "n/a (one action held out)" if abc["auc"] is None else f"{abc['auc']:.3f}"
            log(f"{source} split {s}: abc accuracy {abc['accuracy']:.3f} auc {auc}")
    summary = summarise(rows)
    with atomic_path(out / "summary.json", suffix=".json") as tmp:
        Path(tmp).write_text(json.dumps({"scale": scale, "source": source,
                                         "log": data.source, "patients": patients,
                                         "splits": n_splits, "summary": summary,
                                         "rows": rows}, indent=2))
    md = ["| method | splits | accuracy | AUC |", "| --- | --- | --- | --- |"]
    md += [f"| {s['method']} | {s['splits']} | {s['accuracy_mean']:.4f} ± "
           f"{s['accuracy_std']:.4f} | " + ("n/a" if s["auc_mean"] is None else
                                             f"{s['auc_mean']:.4f} ± {s['auc_std']:.4f}")
           + ("" if s["auc_splits"] == s["splits"] else f" ({s['auc_splits']} splits)") + " |"
           for s in summary]
    with atomic_path(out / "summary.md", suffix=".md") as tmp:
        Path(tmp).write_text("\n".join(md) + "\n")
    plot(summary, out / "ward.png")
    return {"summary": summary, "rows": rows, "out": str(out),
            "seconds": time.perf_counter() - started}
