"""`aoc train NAME`: learn the belief model of a corpus (value mode: AOC; imitation: ABC).
Parses and prints only; the work is in :func:`aoc_cli.api.train`."""

from __future__ import annotations

from typing import Annotated, Optional

import typer

from aoc_cli.belief.config import BeliefConfig
from aoc_cli.cli.common import (BeliefKind, BeliefMode, CorpusArgument, FormatOption, choice,
                                state)
from aoc_cli.report import train_view
from aoc_cli.report.output import ProgressBar, message, resolve_format, write_object
from aoc_cli.settings import SMALL_LOG_ROWS
from aoc_cli.store import DEFAULT_MODEL

#: Flag defaults are the config's (the paper's) defaults.
_D = BeliefConfig()


def train(
    name: CorpusArgument,
    model: Annotated[str, typer.Option(
        "--model", help="Model id to write (models/<ID>/ of the corpus).")] = DEFAULT_MODEL,
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
    from aoc_cli import api  # here: keeps `aoc --help` and bad input from importing torch

    fmt = resolve_format(fmt)
    with ProgressBar("train", transient=True) as bar:
        trained = api.train(
            name, store=state.store, model=model, mode=choice(mode), belief=choice(belief),
            gamma=gamma, value=value, dynamics_weight=dynamics_weight,
            history_length=history_length, hidden=hidden, weight_decay=weight_decay,
            label_smoothing=label_smoothing, critic_steps=critic_steps,
            critic_bc_weight=critic_bc_weight, belief_dim=belief_dim, max_epochs=epochs,
            batch_size=batch_size, lr=lr, patience=patience, val_fraction=val_fraction,
            seed=seed, threads=threads, dropout=dropout, class_weight=class_weight,
            paper=paper, overwrite=overwrite, progress=bar, log=message)
    for line in train_view.notes(trained):
        message(line)
    write_object(train_view.shown(trained, fmt), fmt, title=f"aoc train {name} --model {model}")


def register(app: typer.Typer) -> None:
    app.command("train")(train)
