"""Train a corpus's belief model as ``aoc train`` does, in one call: the settings checked, the
settings the log's evidence decides under the ones given (:mod:`aoc_cli.training.evidence`), the
small-log defaults and the choice of the settings left open by validation
(:mod:`aoc_cli.training.tuning`), one writer per model id, the inputs checked against the
corpus's content hash, then training (:func:`aoc_cli.belief.train.train_model`). ``aoc
train``, ``aoc bench ward`` and the icu-sepsis bench all train through :func:`train_corpus`.

Settings are :class:`~aoc_cli.belief.config.BeliefConfig`'s fields. Those the evidence may
decide or validation may choose (:data:`OPEN`: mode, belief, gamma, value, dynamics_weight,
history_length, hidden, weight_decay) and ``label_smoothing`` are None when not given; every
other field defaults to the paper's value. The controller's settings the evidence decides are
saved with the model (``metrics.controller``): what training decided is one
:class:`~aoc_cli.training.record.TrainingRecord`, saved with the metrics.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, replace
from typing import Callable

from aoc_cli.belief.censoring import censoring_of
from aoc_cli.belief.config import CRITIC_STEP_SECONDS, BeliefConfig
from aoc_cli.belief.data import prepare
from aoc_cli.decompose.k_rule import index_k
from aoc_cli.index.search.neighbourhood import measured_cells, neighbourhood_values
from aoc_cli.progress import Progress
from aoc_cli.store import DEFAULT_MODEL, Corpus, check_name, writing_model
from aoc_cli.threads import thread_limits
from aoc_cli.training import evidence, tuning
from aoc_cli.training.record import Recording, TrainingRecord

#: Settings left to the log's evidence or to validation when None.
OPEN = evidence.TRAINING + ("hidden", "weight_decay")


@dataclass
class Trained:
    """A trained model: its final ``metrics`` (as saved in models/<id>/), the ``config`` it was
    trained with, and whether ``label_smoothing`` was left to the small-log default."""

    corpus: str
    model: str
    metrics: dict
    config: BeliefConfig
    smoothing_by_default: bool


def _split(settings: dict) -> tuple[dict, dict, float | None]:
    given = {k: settings.get(k) for k in OPEN}
    smoothing = settings.get("label_smoothing")
    fixed = {k: v for k, v in settings.items() if k not in OPEN and k != "label_smoothing"}
    return given, {**fixed, "label_smoothing": smoothing or 0.0}, smoothing


def _config(given: dict, fixed: dict) -> BeliefConfig:
    """The checked configuration of the settings ``given`` (None: not given; the paper's value
    for a searched one) and the settings ``fixed``."""
    searched = {k: given.get(k) for k in tuning.PAPER}
    config = BeliefConfig(**{k: v for k, v in given.items()
                             if v is not None and k not in tuning.PAPER}, **fixed)
    return tuning.with_defaults(config, searched)


def check_settings(settings: dict) -> BeliefConfig:
    """The settings checked before any corpus is read (an AocError names a bad one)."""
    given, fixed, _ = _split(settings)
    return _config(given, fixed)


def train_corpus(corpus: Corpus, model: str = DEFAULT_MODEL, *, paper: bool = False,
                 select_settings: bool = True, overwrite: bool = False,
                 progress: Progress | None = None,
                 log: Callable[[str], None] | None = None, controller: dict | None = None,
                 choose_controller: bool = False, **settings) -> Trained:
    """Train model ``model`` of ``corpus`` with ``settings`` (BeliefConfig fields; see the
    module docstring); ``paper``: the paper's settings for everything not given (no rules of
    the evidence, no selection); ``select_settings`` False: no choice by validation (the
    evidence's rules still hold). ``log``: the notes ``aoc train`` prints before training (the
    settings the evidence decided and why, the critic's step budget). ``progress``: fitted Q
    evaluation, the candidates tried, then the epochs (or critic steps).

    ``controller``: the controller settings given (:data:`aoc_cli.training.evidence.CONTROLLER`;
    None values: not given), saved with the model as given. ``choose_controller``: choose the
    controller on the validation episodes (:mod:`aoc_cli.training.controller_selection`, as
    ``aoc train`` does), where :func:`aoc_cli.training.evidence.selects_controller` says."""
    note = log or (lambda _text: None)
    given, fixed, smoothing = _split(settings)
    _config(given, fixed)  # the settings checked before the corpus is read
    chosen = {k: v for k, v in (controller or {}).items() if v is not None}
    record, ev = TrainingRecord(dict(chosen)), None
    if not paper:
        started = time.perf_counter()
        ev = evidence.Evidence.of(corpus)
        decided, reasons = evidence.decide(ev, {**given, **chosen})
        given = {**given, **{k: v for k, v in decided.items() if k in OPEN}}
        record = TrainingRecord(
            {**chosen, **{k: v for k, v in decided.items() if k in evidence.CONTROLLER}},
            settings={"evidence": ev.to_dict(), "decided": reasons,
                      "seconds": time.perf_counter() - started})
    searched = {k: given[k] for k in tuning.PAPER}
    config = _config(given, fixed)
    no_search = paper or not select_settings
    config = tuning.with_imitation_defaults(
        corpus, config, {"label_smoothing": smoothing}, paper)
    unsmoothed = tuning.why_no_smoothing(corpus, config, {"label_smoothing": smoothing},
                                         paper)
    if unsmoothed:
        record = replace(record, label_smoothing_rule=unsmoothed)
    if "k" not in chosen and corpus.n_rows > 0:  # the k rule's, recorded with the model
        imitation = config.mode == "imitation" and bool(corpus.discrete)
        record = record.with_controller(k=index_k(config.belief_dim, corpus, imitation)[0])
    measure = ev is not None and not no_search and "epsilon" not in chosen \
        and evidence.held_out(ev, config)
    penalty = ev is not None and evidence.penalises(ev, config, chosen)
    choose = ev is not None and not no_search and choose_controller \
        and evidence.selects_controller(ev, config, chosen)
    # --threads holds for all of it: the FQE's FAISS searches and numpy too, not torch alone
    limits = thread_limits(torch=config.threads, faiss=config.threads, blas=config.threads)
    with writing_model(corpus.path, check_name(model, "model")), limits:  # one writer a model
        metrics = _train(corpus, config, model, record, overwrite=overwrite,
                         open_names=tuning.open_settings(corpus, config, searched, no_search),
                         defaults_note=tuning.why_no_search(corpus, config, searched, paper,
                                                            select_settings),
                         progress=progress, note=note, measure=measure, choose=choose,
                         penalty=penalty)
    return Trained(corpus.name, model, metrics, config,
                   smoothing is None and config.label_smoothing > 0)


def _train(corpus, config: BeliefConfig, model: str, record: TrainingRecord, *,
           overwrite: bool, open_names: list[str], defaults_note: str | None,
           progress: Progress | None, note: Callable[[str], None], measure: bool = False,
           choose: bool = False, penalty: bool = False) -> dict:
    """Check the inputs (and the corpus's content hash), then train; with ``open_names``,
    choose those settings by validation first (aoc_cli.training.tuning). ``record``: what
    training decided so far (the settings the evidence decided), saved with the metrics;
    ``measure``: decide the controller's epsilon on the validation episodes after training
    (aoc_cli.training.epsilon_rule), into the record's ``controller`` before the model is
    saved; ``choose``: another such ``inspect``, the controller chosen on the validation
    episodes (:mod:`aoc_cli.training.controller_selection`); ``penalty``: rule 2's support
    penalty measured on the row values once they exist
    (:func:`aoc_cli.training.evidence.state_penalty`), into the record."""
    name = corpus.name
    fqe = config.mode == "value" and config.value == "fqe"
    if fqe and progress is not None:
        progress(0, 1, f"fitted Q evaluation of {name}")
    # lazy: torch (and FAISS: the epsilon rule, the controller's selection), settings checked
    from aoc_cli.belief import stream, train as trainer
    from aoc_cli.training import controller_selection, epsilon_rule
    trainer.pick_device(config.device)  # a GPU asked for where torch sees none: before the targets
    prepared = prepare(corpus, config, model, overwrite, progress=progress if fqe else None)
    corpus.verify_content()  # the columns prepare read are cached: hashing reads nothing again
    if penalty and prepared.values is not None:
        started = time.perf_counter()
        z, reason = evidence.state_penalty(corpus, prepared.values, config.gamma,
                                           censoring_of(corpus))
        reason["seconds"] = time.perf_counter() - started
        if z is not None:
            record = record.with_controller(support_penalty=z)
        record = record.deciding(reason).with_settings(
            support_penalty={k: v for k, v in reason.items() if k not in ("setting", "why")})
    if (config.mode == "value" and corpus.discrete and prepared.values is not None
            and record.controller.get("do_no_harm") == "on" and prepared.neighbourhood is None):
        prepared, record = _neighbourhood(corpus, config, prepared, record, progress)

    total = config.max_epochs
    if config.belief == "critic":  # counted in gradient steps, not epochs
        total, rule = config.critic_steps_for(corpus.n_rows, len(prepared.train_rows))
        seconds = total * CRITIC_STEP_SECONDS * config.batch_size / 500
        note(f"training the critic: {total:,} gradient steps ({rule}), about "
             f"{duration(seconds)} at {CRITIC_STEP_SECONDS * config.batch_size / 500:.2g} s "
             "a step on one CPU thread (--critic-steps or --epochs to bound it)")
    if progress is not None:
        progress(0, total, f"training {name}/{model}")
    if open_names:
        return tuning.select_and_train(corpus, config, open_names, model, overwrite,
                                       prepared, progress, record)
    if defaults_note:
        record = replace(record, selection={"searched": [], "why": defaults_note})
    recording = Recording(record)  # the hooks below record into it while the belief trains
    inspect = epsilon_rule.recording_hook(corpus, config.seed, recording, progress) \
        if measure and not stream.streams(corpus, config) else None
    if choose and not stream.streams(corpus, config):
        inspect = controller_selection.recording_hook(corpus, config, record.controller["k"],
                                                      recording, progress)
    return trainer.train_model(corpus, config, model, overwrite=overwrite, progress=progress,
                               prepared=prepared, extra=recording, inspect=inspect)


def _neighbourhood(corpus, config: BeliefConfig, prepared, record: TrainingRecord, progress):
    """Rule 7's values of the rows (FQE over the log's neighbourhoods,
    :func:`aoc_cli.index.search.neighbourhood.neighbourhood_values`) where the belief's own
    target is another (``--value return``, say): into the prepared data (saved with the
    model) and what it measured into the record (``settings.do_no_harm``)."""
    values, info = neighbourhood_values(corpus.observations, corpus.rewards,
                                        corpus.episode_starts, config.gamma,
                                        censoring_of(corpus), progress=progress,
                                        measured=measured_cells(corpus))
    if record.settings is not None:
        kept = {k: v for k, v in info.items() if k not in ("rows", "space")}   # (N, ...)
        record = record.with_settings(do_no_harm={**kept, "value_mean": float(values.mean())})
    return replace(prepared, neighbourhood=values, space=info["space"]), record


def duration(seconds: float) -> str:
    """``40 s``, ``12 min``, ``1.5 h``."""
    if seconds < 90:
        return f"{max(1, round(seconds))} s"
    if seconds < 90 * 60:
        return f"{round(seconds / 60)} min"
    return f"{seconds / 3600:.1f} h"
