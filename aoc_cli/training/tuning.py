"""Settings that hold up on small logs: ``aoc train`` chooses what the user did not fix.

On a small corpus (at most :data:`SELECT_MAX_ROWS` rows) whose model imitates discrete actions
(ABC on a reward-free log, e.g. ward), the paper's settings (a 4-step GRU history, 128 units,
no weight decay) can overfit or underfit what the data supports, and nothing tells the user.
So, for the settings the user leaves open, ``aoc train`` trains candidates on
:data:`FOLDS` validation folds of whole episodes (cross-validation by episode, e.g. by
patient: disjoint blocks of the usual validation size from one random order of the episodes,
the first being the usual split, :func:`aoc_cli.belief.data.episode_folds`) and scores each on
the held-out episodes by two figures, each the mean over the folds:

* the **log-loss**, the cross-entropy of the logged action under the model's head;
* the **AUC** of ABC's own scores (each held-out row decomposed over the fold's training rows,
  every score the sum over the decision's named rows, as ``aoc evaluate`` scores it:
  :func:`abc_validation`), over the folds whose held-out steps hold more than one action.

The rule (:func:`choose_rule`), stated before any result was read: among the candidates whose
mean AUC is within :data:`AUC_MARGIN` of the best mean AUC, the one with the lowest mean
log-loss, a later candidate replacing an earlier (simpler) one only when its log-loss is lower
by more than :data:`MARGIN` (relative). The settings are searched one at a time, in order:

1. history length L in (0, 1, 4);
2. then the width (GRU and hidden units) in (128, 64, 256) at the chosen L;
3. then Adam's weight decay in (0, 1e-4, 1e-3).

The log-loss ranks candidates with less noise than the AUC (every held-out step counts, not
only the few treated ones), and the AUC guards what the user gets: a candidate whose
decisions, scored from their named rows, rank the held-out steps worse by more than the margin
is not chosen for a lower loss. One validation split is not enough on a ward-sized log: on one
of 30 patient splits a search on one split kept L = 4 by 2.7%, and the other seeds' splits
(which draw other validation patients) chose L = 1 (docs/design.md, "Settings chosen on small
logs").
Candidates stop early with patience :data:`SEARCH_PATIENCE` (at most the user's); the chosen
settings are then trained on the usual split with the user's patience and saved. What was
tried (each candidate's log-loss and AUC on every fold and their means), what was chosen and
why go to the output and to the model's config (``metrics.selection``).

**Where it runs** (:func:`searches`): only for imitation of discrete actions, where it was
measured (docs/results/ward.md). For a decision's accountability the action's validation
loss is the thing decided (the head and ABC both score actions); a value model's validation
loss is not: on the maze (19,138 rows) every candidate had a validation R^2 of 0.998, the search
kept width 256 and its weight decay, and AOC on that belief failed every episode (success 0.0,
1.0 with the paper's settings; docs/design.md "Settings chosen on small logs"). So value-mode
models (every belief), continuous imitation, corpora over the limit and ``--paper`` take the
paper's value (or the one the log's evidence decides, aoc_cli.training.evidence) for whatever is
open; ``--no-select`` skips the search.

After training, :func:`baseline_check` says when the model is no better than predicting the
majority action (discrete) or the mean (continuous, value) on the held-out episodes.
"""

from __future__ import annotations

import time
from dataclasses import replace

import numpy as np

from aoc_cli.belief.config import BeliefConfig
from aoc_cli.belief.data import episode_folds, episode_rows
from aoc_cli.belief.row_labels import default_row_smoothing, subset_scores
from aoc_cli.index.search.strata import PER_ACTION
from aoc_cli.metrics import auc
from aoc_cli.settings import SMALL_LOG_ROWS
from aoc_cli.training.record import TrainingRecord

#: Up to this many rows the settings are chosen by validation (aoc_cli.settings).
SELECT_MAX_ROWS = SMALL_LOG_ROWS
#: The settings searched, in order, with their candidate values (the first is tried first).
SEARCH: tuple[tuple[str, tuple], ...] = (
    ("history_length", (0, 1, 4)),
    ("hidden", (128, 64, 256)),
    ("weight_decay", (0.0, 1e-4, 1e-3)),
)
#: The paper's value of each searched setting (used when a setting is open and no search runs).
PAPER = {name: BeliefConfig.__dataclass_fields__[name].default for name, _values in SEARCH}
#: A later candidate must have a mean log-loss lower than the current choice's by more than
#: this (relative).
MARGIN = 0.01
#: Candidates whose mean held-out ABC AUC is below the best mean AUC by more than this are
#: not chosen.
AUC_MARGIN = 0.01
SEARCH_PATIENCE = 5
#: Validation folds of whole episodes each candidate is trained and scored on (fewer when the
#: corpus has fewer whole blocks of the validation size); the first is the usual split.
FOLDS = 3
#: How much better than the majority / mean the model must be not to be flagged.
BASELINE_MARGIN = 0.005


def searches(corpus, config: BeliefConfig, paper: bool = False) -> bool:
    """Whether open settings are chosen by validation: the model imitates discrete actions,
    the corpus has at most :data:`SELECT_MAX_ROWS` rows and ``paper`` is off."""
    return (not paper and config.mode == "imitation" and bool(corpus.discrete)
            and corpus.n_rows <= SELECT_MAX_ROWS)


def open_settings(corpus, config: BeliefConfig, given: dict, paper: bool = False) -> list[str]:
    """The settings to search: those of :data:`SEARCH` the user did not give (``given``:
    name -> value or None), where :func:`searches` holds; else none."""
    if not searches(corpus, config, paper):
        return []
    return [name for name, _values in SEARCH if given.get(name) is None]


def with_defaults(config: BeliefConfig, given: dict) -> BeliefConfig:
    """``config`` with the paper's value for every searched setting left open."""
    return replace(config, **{k: (v if given.get(k) is None else given[k])
                              for k, v in PAPER.items()})


#: Imitation of discrete actions on a small corpus: the training loss's label smoothing
#: when the user gives none (docs/design.md, "Candidates of every action"), where it gives
#: no action more than its share of the log (:func:`smoothing_fits`).
LABEL_SMOOTHING = 0.1


def rarest_share(corpus) -> float | None:
    """The share of the rows of the least logged action among those logged (None: no rows)."""
    actions = np.asarray(corpus.actions, dtype=np.int64).reshape(-1)
    counts = np.bincount(actions)
    counts = counts[counts > 0]
    return float(counts.min() / len(actions)) if len(actions) else None


def smoothing_fits(corpus) -> bool:
    """Whether :data:`LABEL_SMOOTHING` suits the log: the smoothed target gives every action
    LABEL_SMOOTHING / n (n the actions), which must not exceed the rarest logged action's
    share of the rows (ward: 12-14% treated, 0.05 a target; medkit's ward log: 1.1%, where
    the target would tell every untreated row the rare action is 5x likelier than the log
    does, and ABC's held-out AUC fell from 0.99 to 0.93 on a split: docs/design.md)."""
    share = rarest_share(corpus)
    return share is not None and LABEL_SMOOTHING / int(corpus.n_actions) <= share


def with_imitation_defaults(corpus, config: BeliefConfig, given: dict,
                            paper: bool = False) -> BeliefConfig:
    """``config`` with :data:`LABEL_SMOOTHING` when ``given`` has no ``label_smoothing``
    (None), the model imitates discrete actions, the corpus is small (settings chosen by
    validation: :func:`open_settings`'s rule), the smoothing gives no action more than its
    share of the log (:func:`smoothing_fits`) and ``paper`` is off; else the paper's 0 for a
    smoothing left open. The value is saved in the model's config."""
    if given.get("label_smoothing") is not None:
        return replace(config, label_smoothing=float(given["label_smoothing"]))
    on = searches(corpus, config, paper) and smoothing_fits(corpus)
    return replace(config, label_smoothing=LABEL_SMOOTHING if on else 0.0)


def why_no_smoothing(corpus, config: BeliefConfig, given: dict, paper: bool) -> str | None:
    """Why a smoothing left open is 0 where settings are searched: the rarest action's share
    is below what the smoothing would give it (None otherwise)."""
    if given.get("label_smoothing") is not None or not searches(corpus, config, paper) \
            or smoothing_fits(corpus):
        return None
    n = int(corpus.n_actions)
    return (f"no label smoothing: the rarest action is {rarest_share(corpus):.1%} of the rows, "
            f"under the {LABEL_SMOOTHING / n:.1%} a smoothing of {LABEL_SMOOTHING:g} would give "
            f"each of the {n} actions")


def why_no_search(corpus, config: BeliefConfig, given: dict, paper: bool,
                  select_settings: bool = True) -> str | None:
    """Why open settings took the paper's values (None when nothing was open)."""
    left = [k for k in PAPER if given.get(k) is None]
    if not left:
        return None
    if paper:
        return "the paper's settings, as asked (no rules of the log's evidence, no selection)"
    if not select_settings:
        return "the paper's settings for those left open, as asked (--no-select)"
    if config.mode != "imitation":
        return ("value mode: the paper's settings (settings are chosen by validation only "
                "when imitating discrete actions; a lower value loss is not a better "
                "controller)")
    if not corpus.discrete:
        return ("continuous actions: the paper's settings (settings are chosen by validation "
                "only when imitating discrete actions)")
    return (f"the corpus has {corpus.n_rows} rows, over the {SELECT_MAX_ROWS} up to which "
            "settings are chosen by validation: the paper's settings")


def abc_validation(actions: np.ndarray, n_actions: int, k: int | None = None):
    """An ``inspect`` hook for :func:`aoc_cli.belief.train.train_model` (discrete imitation):
    decompose the validation rows' beliefs (float32, as the index holds them) over the
    training rows' beliefs and score the decisions as ``aoc evaluate`` does (the score of an
    action = its weight in the minimal corpus subset; the candidates and k as ``aoc index``
    takes them for the training rows, the nearest rows of each action, unless k is given).
    Returns ``val_abc_accuracy``, ``val_abc_auc``, ``val_abc_k``. ``actions`` (N,) the
    corpus's discrete actions."""
    # lazy: torch and FAISS, for the validation hook; choosing settings must not load them
    import torch

    from aoc_cli.decompose import decompose, per_action_k
    from aoc_cli.index.search import BeliefIndex, PerAction

    actions = np.asarray(actions, dtype=np.int64)

    def inspect(net, inputs, data, _norm=None) -> dict:
        rows = torch.as_tensor(np.concatenate([data.train_rows, data.val_rows]),
                               device=inputs.obs.device)
        with torch.no_grad():
            b = torch.cat([net(*inputs.batch(rows[i:i + 65536]))[0]
                           for i in range(0, len(rows), 65536)]).cpu().numpy()
        n_tr = len(data.train_rows)
        a_tr, y = actions[data.train_rows], actions[data.val_rows]
        search = PerAction(BeliefIndex.build(b[:n_tr], kind="flat"), a_tr)
        kk = k if k is not None else per_action_k(b.shape[1], len(search.masks))
        dec = decompose(b[:n_tr], b[n_tr:], k=kk, index=search)
        lam = default_row_smoothing(True, PER_ACTION)
        head = (net.head.weight.detach().cpu().double().numpy(),  # the logits' (n, d_b), (n,)
                net.head.bias.detach().cpu().double().numpy())
        scores = subset_scores(dec.rows, dec.weights, a_tr, n_actions, b[:n_tr], head, lam)
        return {"val_abc_accuracy": float(np.mean(scores.argmax(1) == y)),
                "val_abc_auc": auc(y, scores), "val_abc_k": int(min(kk, n_tr)),
                "val_abc_row_smoothing": lam}

    return inspect


def abc_scores(rows: np.ndarray, weights: np.ndarray, actions: np.ndarray,
               n_actions: int) -> np.ndarray:
    """(Q, n_actions) each action's weight in the minimal corpus subsets ``rows`` (Q, m)
    (-1 padded) with ``weights`` (Q, m), ``actions`` (N,) the corpus rows' actions: the
    paper's score (the rows' labels unsmoothed, :func:`aoc_cli.belief.row_labels.subset_scores`
    with lambda 0)."""
    return subset_scores(rows, weights, actions, n_actions)


def fold_data(corpus, prepared, config: BeliefConfig, folds: int) -> list:
    """The validation folds of the search: ``prepared`` (a
    :class:`~aoc_cli.belief.data.TrainingData`, the usual split) with the training and
    validation episodes of each of :func:`aoc_cli.belief.data.episode_folds`'s folds (the
    first is ``prepared``'s own split)."""
    starts = corpus.episode_starts
    return [replace(prepared, train_episodes=tr, val_episodes=va,
                    train_rows=episode_rows(starts, tr), val_rows=episode_rows(starts, va))
            for tr, va in episode_folds(corpus.n_episodes, config.val_fraction, config.seed,
                                        folds)]


def choose(values: tuple, loss) -> tuple:
    """(the value chosen, its loss) among ``values`` in order: a value replaces the current
    choice only when ``loss(value)`` (a candidate's mean validation loss over the folds) is
    lower than the current one's by more than :data:`MARGIN` (relative)."""
    best, best_loss = values[0], loss(values[0])
    for v in values[1:]:
        if loss(v) < best_loss * (1 - MARGIN):
            best, best_loss = v, loss(v)
    return best, best_loss


def eligible(values: tuple, auc) -> tuple:
    """The ``values`` (in order) whose ``auc(value)`` (a candidate's mean held-out AUC, None
    where no fold's held-out steps hold two actions) is within :data:`AUC_MARGIN` of the best;
    all of them when none has an AUC."""
    aucs = {v: auc(v) for v in values}
    known = [a for a in aucs.values() if a is not None]
    if not known:
        return tuple(values)
    top = max(known)
    return tuple(v for v in values if aucs[v] is not None and aucs[v] >= top - AUC_MARGIN)


def choose_rule(values: tuple, loss, auc) -> tuple:
    """The rule of the search (module docstring): (the value chosen, its mean log-loss) by
    :func:`choose` among the values :func:`eligible` keeps by their mean AUC."""
    return choose(eligible(values, auc), loss)


def _mean(xs: list) -> float | None:
    known = [x for x in xs if x is not None]
    return float(np.mean(known)) if known else None


def _fmt(x: float | None) -> str:
    return "n/a" if x is None else f"{x:.4g}"


def select_and_train(corpus, config: BeliefConfig, open_names: list[str], model_id: str,
                     overwrite: bool, prepared, progress=None,
                     training_record: TrainingRecord | None = None) -> dict:
    """Search ``open_names`` (see the module docstring), then train and save the chosen
    configuration as ``model_id``; the final metrics, with ``selection`` (what was tried on
    each fold and why the winner was chosen). ``progress`` (:mod:`aoc_cli.progress`): each
    candidate tried on each fold as a label (its settings and loss), then the final
    training's epochs. ``training_record``: what training decided before, saved with the
    metrics."""
    from aoc_cli.belief.train import train_model  # lazy: torch; settings are checked first

    started = time.perf_counter()
    names = [n for n, _ in SEARCH]
    search_cfg = replace(config, patience=min(config.patience, SEARCH_PATIENCE))
    data = fold_data(corpus, prepared, config, FOLDS)
    tried: dict[tuple, dict] = {}

    hook = abc_validation(corpus.actions, int(corpus.n_actions))

    def run(cfg: BeliefConfig) -> dict:
        """The candidate's record: its settings, log-loss, ABC AUC and accuracy on every
        fold, the means."""
        key = tuple(getattr(cfg, n) for n in names)
        if key not in tried:
            rec: dict = dict(zip(names, key))
            per_fold = []
            for j, fold in enumerate(data):
                m = train_model(corpus, replace(search_cfg, **rec), model_id, overwrite=True,
                                prepared=fold, save=False, inspect=hook)
                per_fold.append(m)
                if progress is not None:
                    progress(0, None, "choosing settings: " + ", ".join(
                        f"{k} {rec[k]}" for k in names)
                        + f" fold {j + 1}/{len(data)} log-loss {m['val_loss']:.4f} AUC "
                        + _fmt(m["val_abc_auc"]))
            rec["val_losses"] = [float(m["val_loss"]) for m in per_fold]
            rec["val_loss"] = float(np.mean(rec["val_losses"]))
            rec["val_aucs"] = [m["val_abc_auc"] for m in per_fold]
            rec["val_auc"] = _mean(rec["val_aucs"])
            rec["val_accuracy"] = float(np.mean([m["val_accuracy"] for m in per_fold]))
            rec["epochs"] = [int(m["epochs"]) for m in per_fold]
            tried[key] = rec
        return tried[key]

    best, reasons = config, []
    for name, values in SEARCH:
        if name not in open_names:
            continue

        def record(v, name=name):
            return run(replace(best, **{name: v}))

        value, loss = choose_rule(values, lambda v: record(v)["val_loss"],
                                  lambda v: record(v)["val_auc"])
        kept = eligible(values, lambda v: record(v)["val_auc"])
        reasons.append(f"{name} {value}: log-loss {loss:.4g} (" + ", ".join(
            f"{v}: log-loss {record(v)['val_loss']:.4g} AUC {_fmt(record(v)['val_auc'])}"
            + ("" if v in kept else " out by AUC") for v in values) + ")")
        best = replace(best, **{name: value})
    selection = {
        "searched": list(open_names),
        "chosen": {n: getattr(best, n) for n in names},
        "why": f"the lowest mean held-out log-loss over {len(data)} folds of episodes among "
               f"the candidates whose mean held-out ABC AUC is within {AUC_MARGIN:g} of the "
               f"best (a candidate must beat the simpler one's log-loss by more than "
               f"{MARGIN:.0%}): " + "; ".join(reasons),
        "folds": len(data),
        "fold_val_episodes": [len(f.val_episodes) for f in data],
        "candidates": list(tried.values()),
        "search_seconds": time.perf_counter() - started,
        "rule": f"settings left open are chosen by cross-validation over episodes on corpora "
                f"of at most {SELECT_MAX_ROWS} rows: log-loss among the candidates within "
                f"{AUC_MARGIN:g} of the best ABC AUC",
        "margins": {"log_loss_relative": MARGIN, "auc": AUC_MARGIN},
    }
    inspect = None
    if config.mode == "imitation" and corpus.discrete:  # ABC's own decisions, validated
        inspect = abc_validation(corpus.actions, int(corpus.n_actions))
    return train_model(corpus, best, model_id, overwrite=overwrite, progress=progress,
                       prepared=prepared,
                       extra={**(training_record.as_dict() if training_record else {}),
                              "selection": selection},
                       inspect=inspect)


def baseline_check(metrics: dict, margin: float = BASELINE_MARGIN) -> str | None:
    """A warning when the model does no better than the trivial predictor on the held-out
    episodes: the majority action (discrete imitation) or the mean (R^2 near 0)."""
    if "val_accuracy" in metrics and "val_majority_accuracy" in metrics:
        acc, maj = metrics["val_accuracy"], metrics["val_majority_accuracy"]
        if acc <= maj + margin:
            return (f"the model is no better than always predicting the majority action: "
                    f"validation accuracy {acc:.3f} against {maj:.3f}")
        return None
    r2 = metrics.get("val_r2")
    if r2 is not None and r2 <= margin:
        return (f"the model is no better than predicting the mean: validation R^2 {r2:.3f}")
    return None
