"""`aoc train NAME`: learn the belief model of a corpus (value mode: AOC; imitation: ABC)."""

from __future__ import annotations

from typing import Annotated, Optional

import typer

from aoc_cli.belief import select, task_settings
from aoc_cli.belief.config import CRITIC_STEP_SECONDS, BeliefConfig
from aoc_cli.belief.data import prepare
from aoc_cli.cli.common import (BeliefKind, BeliefMode, CorpusArgument, FormatOption, choice,
                                get_store)
from aoc_cli.report.output import ProgressBar, message, resolve_format, write_object
from aoc_cli.settings import SMALL_LOG_ROWS

#: Flag defaults are the config's (the paper's) defaults.
_D = BeliefConfig()


def train(
    name: CorpusArgument,
    model: Annotated[str, typer.Option(
        "--model", help="Model id to write (models/<ID>/ of the corpus).")] = "default",
    mode: Annotated[Optional[BeliefMode], typer.Option(
        "--mode", case_sensitive=False,
        help="value: b(o, a, h) predicts v (AOC); imitation: b(o, h) predicts the action "
             "(ABC, reward-free data). Default: the task's (ward: imitation), else "
             "value.")] = None,
    belief: Annotated[Optional[BeliefKind], typer.Option(
        "--belief", case_sensitive=False,
        help="Value mode: what the belief is trained on: value (regress --value), critic (an "
             "offline TD3+BC critic's last hidden layer), reward (a model of the immediate "
             "reward) or dynamics (value + the o' - o head). The linear head maps every "
             "belief to --value. Default: value.")] = None,
    critic_steps: Optional[int] = typer.Option(
        None, "--critic-steps", help="--belief critic: gradient steps (default: one per 10 "
                                     "rows, between 500 and 10,000, at most --epochs passes "
                                     "over the training rows)."),
    critic_bc_weight: float = typer.Option(_D.critic_bc_weight, "--critic-bc-weight",
                                           help="--belief critic: weight of the actor's "
                                                "behaviour-cloning term (0: plain TD3)."),
    value: Optional[str] = typer.Option(None, "--value",
                                        help="Value target: return (discounted return-to-go, "
                                             "the default), mean-return, reward, fqe (the "
                                             "behaviour's Q by fitted Q evaluation, "
                                             "bootstrapped through the log), or a numeric "
                                             "corpus column."),
    gamma: Optional[float] = typer.Option(
        None, "--gamma", help="Discount of --value return and fqe (default: the task's: "
                              "pendulum-het-upright 0.9; else 0.99)."),
    history_length: Optional[int] = typer.Option(
        None, "--history-length", help="Previous transitions of the episode the GRU reads "
                                       "(0: no history; default: chosen by validation among "
                                       "0, 1, 4 when imitating discrete actions on up to "
                                       f"{SMALL_LOG_ROWS:,} rows; else the task's, or 4)."),
    dynamics_weight: Optional[float] = typer.Option(None, "--dynamics-weight",
                                          help="Value mode: weight of the auxiliary loss that "
                                               "makes the belief also predict o' - o "
                                               "(0: the paper's objective alone; "
                                               "--belief dynamics: 1 unless given)."),
    belief_dim: int = typer.Option(_D.belief_dim, "--belief-dim", help="Belief dimension d_b."),
    hidden: Optional[int] = typer.Option(
        None, "--hidden", help="Units of the GRU and hidden layers (default: chosen among 128, "
                               "64, 256 when imitating discrete actions on small corpora, "
                               "else 128)."),
    weight_decay: Optional[float] = typer.Option(
        None, "--weight-decay", help="Adam's L2 penalty (default: chosen among 0, 1e-4, 1e-3 "
                                     "when imitating discrete actions on small corpora, "
                                     "else 0)."),
    dropout: float = typer.Option(_D.dropout, "--dropout",
                                  help="Dropout after the two hidden layers while training "
                                       "(0: none, the paper's)."),
    class_weight: str = typer.Option(_D.class_weight, "--class-weight",
                                     help="Imitation, discrete actions: none, or balanced "
                                          "(each action's loss weighted by its rarity)."),
    label_smoothing: Optional[float] = typer.Option(
        None, "--label-smoothing", help="Imitation, discrete actions: label smoothing of the "
                                        "training loss (0: none, the paper's; default: 0.1 "
                                        f"on corpora of up to {SMALL_LOG_ROWS:,} rows, else 0)."),
    paper: bool = typer.Option(False, "--paper", help="The paper's settings for everything "
                                                      "not given (L 4, 128 units, no weight "
                                                      "decay, no label smoothing, gamma "
                                                      "0.99): no selection, not the task's "
                                                      "own settings."),
    epochs: int = typer.Option(_D.max_epochs, "--epochs", help="Maximum epochs (early stopping ends "
                                                     "sooner; --belief critic: at most this "
                                                     "many passes over the training rows)."),
    batch_size: int = typer.Option(_D.batch_size, "--batch-size", help="Mini-batch rows."),
    lr: float = typer.Option(_D.lr, "--lr", help="Adam learning rate."),
    patience: int = typer.Option(_D.patience, "--patience",
                                 help="Stop after this many epochs without a better "
                                      "validation loss."),
    val_fraction: float = typer.Option(_D.val_fraction, "--val-fraction",
                                       help="Share of episodes held out for validation."),
    seed: Annotated[int, typer.Option(
        "--seed", help="Seed of the split, initialisation and batches (reproducible on "
                       "CPU).")] = _D.seed,
    threads: Optional[int] = typer.Option(None, "--threads",
                                          help="CPU threads (default: all cores)."),
    overwrite: bool = typer.Option(False, "--overwrite", help="Replace an existing model id."),
    fmt: FormatOption = None,
) -> None:
    """Train the belief model b and linear head l of corpus NAME; print the final metrics."""
    fmt = resolve_format(fmt)
    given = {"mode": choice(mode) if mode is not None else None,
             "belief": choice(belief) if belief is not None else None, "gamma": gamma,
             "value": value, "dynamics_weight": dynamics_weight,
             "history_length": history_length, "hidden": hidden, "weight_decay": weight_decay}
    fixed = dict(critic_steps=critic_steps, critic_bc_weight=critic_bc_weight,
                 belief_dim=belief_dim, max_epochs=epochs, batch_size=batch_size, lr=lr,
                 patience=patience, val_fraction=val_fraction, seed=seed, threads=threads,
                 dropout=dropout, class_weight=class_weight,
                 label_smoothing=label_smoothing or 0.0)
    _config(given, fixed)  # the flags checked before the store is read
    corpus = get_store().corpus(name)
    task, settings = task_settings.for_corpus(corpus, paper)
    given, from_task = task_settings.resolve(given, settings)
    searched = {k: given[k] for k in select.PAPER}
    config = _config(given, fixed)
    config = select.with_imitation_defaults(
        corpus, config, {"label_smoothing": label_smoothing}, paper).validate()
    if from_task:
        message(task_settings.describe(task, from_task))
    extra = {"task_settings": {"task": task, "settings": from_task}} if task else {}
    from aoc_cli.store import check_name, writing_model

    with writing_model(corpus.path, check_name(model, "model")):  # one writer per model id
        metrics = _train(corpus, config, model, overwrite,
                         select.open_settings(corpus, config, searched, paper),
                         select.why_no_search(corpus, config, searched, paper), extra)
    score = (f"val R^2 {metrics['val_r2']:.3f}" if "val_r2" in metrics
             else f"val accuracy {metrics['val_accuracy']:.3f} (majority "
                  f"{metrics['val_majority_accuracy']:.3f})")
    unit = "steps" if metrics.get("belief") == "critic" else "epochs"
    message(f"trained {name}/{model}: {metrics['mode']} ({metrics.get('belief', 'value')} "
            f"belief), {metrics['epochs']} {unit} (best "
            f"{metrics['best_epoch']}), {score}, {metrics['seconds']:.0f} s")
    chosen = metrics.get("selection") if (metrics.get("selection") or {}).get("searched") \
        else None
    if chosen:
        message("chose " + ", ".join(f"{k} {v}" for k, v in chosen["chosen"].items()
                                     if k in chosen["searched"]) + " by " + chosen["why"])
    if metrics.get("val_abc_accuracy") is not None:
        auc = metrics.get("val_abc_auc")
        message(f"ABC's own decisions on the validation episodes (k {metrics['val_abc_k']}): "
                f"accuracy {metrics['val_abc_accuracy']:.3f}"
                + ("" if auc is None else f", AUC {auc:.3f}"))
    if label_smoothing is None and config.label_smoothing > 0:
        message(f"label smoothing {config.label_smoothing:g} (the default for imitating "
                "discrete actions on a small corpus; --label-smoothing 0 for the paper's)")
    warning = select.baseline_check(metrics)
    if warning:
        message(f"[yellow]warning:[/] {warning}")
    shown = metrics
    if fmt == "table" and chosen:  # the candidates are in the JSON output and config.json
        shown = {**metrics, "selection": ", ".join(f"{k} {v}" for k, v in
                                                   chosen.get("chosen", {}).items())}
    if not chosen and "selection" in metrics:
        message(f"settings: {metrics['selection']['why']}")
    if fmt == "table" and not chosen and "selection" in metrics:
        shown = {**metrics, "selection": metrics["selection"]["why"]}
    if fmt == "table" and "task_settings" in metrics:
        own = metrics["task_settings"]
        shown = {**shown, "task_settings": f"{own['task']}: " + (", ".join(
            f"{k} {v}" for k, v in own["settings"].items()) or "none")}
    write_object(shown, fmt, title=f"aoc train {name} --model {model}")


def _config(given: dict, fixed: dict) -> BeliefConfig:
    """The checked configuration of the settings ``given`` (None: not given; the paper's value
    for a searched one) and the flags ``fixed``."""
    searched = {k: given.get(k) for k in select.PAPER}
    config = BeliefConfig(**{k: v for k, v in given.items()
                             if v is not None and k not in select.PAPER}, **fixed)
    return select.with_defaults(config, searched).validate()


def _train(corpus, config: BeliefConfig, model: str, overwrite: bool, open_names: list[str],
           defaults_note: str | None, extra: dict) -> dict:
    """Check the inputs (and the corpus's content hash), then train with a progress bar;
    with ``open_names``, choose those settings by validation first (aoc_cli.belief.select).
    ``extra``: more entries of the saved metrics (the task's settings)."""
    name = corpus.name
    if config.mode == "value" and config.value == "fqe":
        with ProgressBar(f"fitted Q evaluation of {name}", 1, transient=True) as bar:
            prepared = prepare(corpus, config, model, overwrite, progress=bar)
    else:
        prepared = prepare(corpus, config, model, overwrite)
    corpus.verify_content()  # the columns prepare read are cached: hashing reads nothing again
    from aoc_cli.belief.train import train_model  # imports torch: only once the input is good

    critic = config.belief == "critic"  # counted in gradient steps, not epochs
    total = config.max_epochs
    if critic:
        total, rule = config.critic_steps_for(corpus.n_rows, len(prepared.train_rows))
        seconds = total * CRITIC_STEP_SECONDS * config.batch_size / 500
        message(f"training the critic: {total:,} gradient steps ({rule}), about "
                f"{_duration(seconds)} at {CRITIC_STEP_SECONDS * config.batch_size / 500:.2g} s "
                "a step on one CPU thread (--critic-steps or --epochs to bound it)")
    with ProgressBar(f"training {name}/{model}", total, transient=True) as bar:
        if open_names:
            return select.select_and_train(corpus, config, open_names, model, overwrite,
                                           prepared, bar, extra)
        if defaults_note:
            extra = {**extra, "selection": {"searched": [], "why": defaults_note}}
        return train_model(corpus, config, model, overwrite=overwrite, progress=bar,
                           prepared=prepared, extra=extra or None)


def _duration(seconds: float) -> str:
    """``40 s``, ``12 min``, ``1.5 h``."""
    if seconds < 90:
        return f"{max(1, round(seconds))} s"
    if seconds < 90 * 60:
        return f"{round(seconds / 60)} min"
    return f"{seconds / 3600:.1f} h"


def register(app: typer.Typer) -> None:
    app.command("train")(train)
