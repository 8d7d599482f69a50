"""What ``aoc train`` prints of a trained model (:class:`aoc_cli.training.fit.Trained`): the
notes on stderr (the score, the settings chosen and why, ABC's own validation, a model no
better than the trivial predictor) and the metrics table."""

from __future__ import annotations

from typing import TYPE_CHECKING

from aoc_cli.training import evidence, tuning
from aoc_cli.training.evidence import Evidence

if TYPE_CHECKING:  # an annotation only: aoc --help (which imports this view) loads no training
    from aoc_cli.training.fit import Trained


def _chosen(metrics: dict) -> dict | None:
    return metrics.get("selection") if (metrics.get("selection") or {}).get("searched") \
        else None


def candidate_lines(selection: dict) -> list[str]:
    """One line per candidate of the selection: its settings, mean held-out log-loss and ABC
    AUC over the folds, and each fold's."""
    def fmt(x):
        return "n/a" if x is None else f"{x:.4f}"

    out = []
    for c in selection.get("candidates", []):
        settings = ", ".join(f"{k} {c[k]}" for k in selection["chosen"])
        out.append(f"{settings}: held-out log-loss {fmt(c['val_loss'])}, ABC AUC "
                   f"{fmt(c.get('val_auc'))} (folds: "
                   + "; ".join(f"{fmt(l)} / {fmt(a)}" for l, a in
                               zip(c["val_losses"], c.get("val_aucs") or [None] * len(
                                   c["val_losses"]))) + ")")
    return out


def notes(trained: Trained) -> list[str]:
    """The lines printed after training, in order (rich markup)."""
    metrics, out = trained.metrics, []
    score = (f"val R^2 {metrics['val_r2']:.3f}" if "val_r2" in metrics
             else f"val accuracy {metrics['val_accuracy']:.3f} (majority "
                  f"{metrics['val_majority_accuracy']:.3f})")
    unit = "steps" if metrics.get("belief") == "critic" else "epochs"
    out.append(f"trained {trained.corpus}/{trained.model}: {metrics['mode']} "
               f"({metrics.get('belief', 'value')} belief), {metrics['epochs']} {unit} (best "
               f"{metrics['best_epoch']}), {score}, {metrics['seconds']:.0f} s")
    settings = metrics.get("settings")
    if settings:
        out.append(f"the log's evidence ({evidence.summary(Evidence(**settings['evidence']))}; "
                   f"read in {settings['seconds']:.1f} s) decided what no flag gave:")
        for r in settings["decided"]:
            cost = f" ({r['seconds']:.1f} s)" if "seconds" in r else ""
            out.append(f"  {evidence.describe([r])[0]}{cost}")
        chosen = settings.get("controller_selection")
        if chosen:
            fitted = any(e.get("estimate") is not None for e in chosen["candidates"])
            out.append(f"  the controllers on {chosen['episodes']:,} held-out episodes ("
                       + (f"FQE, {chosen['interval']}; " if fitted else "")
                       + f"{chosen['seconds']:.1f} s):")
            out.extend(f"    {line}" for line in evidence.selection_lines(chosen))
    chosen = _chosen(metrics)
    if chosen:
        out.append("chose " + ", ".join(f"{k} {v}" for k, v in chosen["chosen"].items()
                                        if k in chosen["searched"]) + " by " + chosen["why"])
        out += [f"  {line}" for line in candidate_lines(chosen)]
    if metrics.get("val_abc_accuracy") is not None:
        auc = metrics.get("val_abc_auc")
        out.append(f"ABC's own decisions on the validation episodes (k "
                   f"{metrics['val_abc_k']}): accuracy {metrics['val_abc_accuracy']:.3f}"
                   + ("" if auc is None else f", AUC {auc:.3f}"))
    if trained.smoothing_by_default:
        out.append(f"label smoothing {trained.config.label_smoothing:g} (the default for "
                   "imitating discrete actions on a small corpus; --label-smoothing 0 for the "
                   "paper's)")
    if metrics.get("label_smoothing_rule"):
        out.append(metrics["label_smoothing_rule"])
    warning = tuning.baseline_check(metrics)
    if warning:
        out.append(f"[yellow]warning:[/] {warning}")
    if not chosen and "selection" in metrics:
        out.append(f"settings: {metrics['selection']['why']}")
    return out


def shown(trained: Trained, fmt: str) -> dict:
    """The metrics as printed: in a table, the selection, the settings the log's evidence
    decided and the controller's as one line each (the JSON output and config.json keep them whole)."""
    metrics = shown = trained.metrics
    chosen = _chosen(metrics)
    if fmt == "table" and chosen:
        shown = {**metrics, "selection": ", ".join(f"{k} {v}" for k, v in
                                                   chosen.get("chosen", {}).items())}
    if fmt == "table" and not chosen and "selection" in metrics:
        shown = {**metrics, "selection": metrics["selection"]["why"]}
    if fmt == "table" and "settings" in metrics:
        shown = {**shown, "settings": ", ".join(
            f"{r['setting']} {r['value']}" for r in metrics["settings"]["decided"]) or "none"}
    if fmt == "table" and "controller" in metrics:
        shown = {**shown, "controller": ", ".join(
            f"{k} {v}" for k, v in metrics["controller"].items()) or "the paper's"}
    return shown
