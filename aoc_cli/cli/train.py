"""`aoc train NAME`: learn the belief model of a corpus (value mode: AOC; imitation: ABC).
Parses and prints only; the work is in :func:`aoc_cli.api.train`. Every option but
``--model``, ``--paper``, ``--no-select``, ``--overwrite`` and the five controller settings
saved with the model (``--epsilon``, ``--residual-cap``, ``--support-penalty``, ``--k``,
``--do-no-harm``:
:class:`~aoc_cli.control.config.ControllerConfig`'s) is a :class:`~aoc_cli.belief.config.BeliefConfig`
setting: its help, range, choices and default come from the field (:mod:`aoc_cli.cli.fields`).
"""

from __future__ import annotations

from typing import Annotated, Optional

import typer

import aoc_cli
from aoc_cli.training import tuning
from aoc_cli.belief.config import BeliefConfig
from aoc_cli.control.config import ControllerConfig
from aoc_cli.cli.common import (BeliefKind, BeliefMode, ClassWeight, CorpusArgument, Device,
                                DoNoHarm, FormatOption, choice, state)
from aoc_cli.cli.fields import EVIDENCE, from_field
from aoc_cli.cli import train_view
from aoc_cli.cli.output import ProgressBar, message, resolve_format, write_object
from aoc_cli.settings import SMALL_LOG_ROWS
from aoc_cli.store import DEFAULT_MODEL

_SMALL = f"when imitating discrete actions on up to {SMALL_LOG_ROWS:,} rows"


def _searched(name: str) -> str:
    """The default shown for a setting chosen by validation on a small log."""
    values = ", ".join(f"{v:g}" for v in dict(tuning.SEARCH)[name])
    return (f"decided from the log's evidence, else chosen by validation among {values} "
            f"{_SMALL}, else {{default}}")


def _option(name: str, *flags: str, given: str | None = None):
    return from_field(BeliefConfig, name, *flags, given=given)


#: The controller settings saved with the model: decided, chosen on held-out episodes, or given.
_SAVED = ("saved with the model; given, it is not decided (residual cap, support penalty or "
          "do no harm given: no controller chosen on held-out episodes)")


def _controller(name: str):
    return from_field(ControllerConfig, name, given=_SAVED + ", else {default}" if name != "k"
                      else "the k rule's, " + _SAVED)


_PAPER = ", ".join(f"{k} {v:g}" for k, v in {**tuning.PAPER, "label_smoothing": 0,
                                              "gamma": BeliefConfig.gamma}.items())


def train(
    name: CorpusArgument,
    model: Annotated[str, typer.Option(
        "--model", help="Model id to write (models/<ID>/ of the corpus).")] = DEFAULT_MODEL,
    mode: Optional[BeliefMode] = _option("mode", given=EVIDENCE),
    belief: Optional[BeliefKind] = _option("belief", given=EVIDENCE),
    critic_steps: Optional[int] = _option("critic_steps"),
    critic_bc_weight: float = _option("critic_bc_weight"),
    value: Optional[str] = _option("value", given=EVIDENCE),
    gamma: Optional[float] = _option("gamma", given=EVIDENCE),
    history_length: Optional[int] = _option("history_length",
                                            given=_searched("history_length")),
    dynamics_weight: Optional[float] = _option("dynamics_weight", given=EVIDENCE),
    belief_dim: int = _option("belief_dim"),
    hidden: Optional[int] = _option("hidden", given=_searched("hidden")),
    weight_decay: Optional[float] = _option("weight_decay", given=_searched("weight_decay")),
    dropout: float = _option("dropout"),
    class_weight: ClassWeight = _option("class_weight"),
    label_smoothing: Optional[float] = _option(
        "label_smoothing", given=f"{tuning.LABEL_SMOOTHING:g} {_SMALL}, else {{default}}"),
    epsilon: Optional[float] = _controller("epsilon"),
    residual_cap: Optional[float] = _controller("residual_cap"),
    support_penalty: Optional[float] = _controller("support_penalty"),
    k: Optional[int] = _controller("k"),
    do_no_harm: Optional[DoNoHarm] = _controller("do_no_harm"),
    paper: bool = typer.Option(False, "--paper", help=f"The paper's settings for everything "
                                                      f"not given ({_PAPER}): no selection, "
                                                      "no rules of the log's evidence."),
    no_select: bool = typer.Option(False, "--no-select",
                                   help="Choose nothing by validation on held-out episodes "
                                        "(the rules of the log's evidence still decide)."),
    epochs: int = _option("max_epochs"),
    batch_size: int = _option("batch_size"),
    lr: float = _option("lr"),
    patience: int = _option("patience"),
    val_fraction: float = _option("val_fraction"),
    seed: int = _option("seed"),
    threads: Optional[int] = _option("threads"),
    device: Device = _option("device"),
    overwrite: bool = typer.Option(False, "--overwrite", help="Replace an existing model id."),
    fmt: FormatOption = None,
) -> None:
    """Train the belief model b and linear head l of corpus NAME; print the final metrics."""
    fmt = resolve_format(fmt)
    with ProgressBar("train", transient=True) as bar:
        trained = aoc_cli.train(
            name, store=state.store, model=model, belief=dict(
                mode=choice(mode), belief=choice(belief), gamma=gamma, value=value,
                dynamics_weight=dynamics_weight, history_length=history_length, hidden=hidden,
                weight_decay=weight_decay, label_smoothing=label_smoothing,
                critic_steps=critic_steps, critic_bc_weight=critic_bc_weight,
                belief_dim=belief_dim, max_epochs=epochs, batch_size=batch_size, lr=lr,
                patience=patience, val_fraction=val_fraction, seed=seed, threads=threads,
                device=choice(device), dropout=dropout, class_weight=choice(class_weight)),
            paper=paper, no_select=no_select, overwrite=overwrite, progress=bar, log=message,
            controller={"epsilon": epsilon, "residual_cap": residual_cap,
                        "support_penalty": support_penalty, "k": k,
                        "do_no_harm": choice(do_no_harm)})
    for line in train_view.notes(trained):
        message(line)
    write_object(train_view.shown(trained, fmt), fmt, title=f"aoc train {name} --model {model}")


def register(app: typer.Typer) -> None:
    app.command("train")(train)
