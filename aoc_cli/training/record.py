"""What ``aoc train`` decided, as one typed record saved with the model's metrics
(:class:`TrainingRecord`): the controller's settings, the settings from the log's evidence and
why, the label-smoothing rule, the settings chosen by validation. Each step of training lays
its findings over the record (a new record: it is frozen); the steps that run inside the
belief's training (the epsilon rule, the controller's selection: ``inspect`` hooks) do so
through a :class:`Recording`, which training reads once they ran.

The saved metrics hold :meth:`TrainingRecord.as_dict`: ``settings`` (when the evidence was
read), ``controller``, ``label_smoothing_rule`` and ``selection`` (when given), in that order.
"""

from __future__ import annotations

from dataclasses import dataclass, replace


@dataclass(frozen=True)
class TrainingRecord:
    """``controller``: the controller settings saved with the model (``metrics.controller``:
    given, decided from the evidence, measured or chosen on held-out episodes; the k).
    ``settings``: the log's evidence, the settings decided and why (``decided``, one reason
    each), the seconds it took, and what later steps measured (``support_penalty``,
    ``controller_selection``); None with ``--paper`` (no evidence read).
    ``label_smoothing_rule``: why a small log's label smoothing was not applied.
    ``selection``: the settings chosen by validation, or why none were searched."""

    controller: dict
    settings: dict | None = None
    label_smoothing_rule: str | None = None
    selection: dict | None = None

    def with_controller(self, **settings) -> "TrainingRecord":
        """The controller's ``settings`` laid over the record's."""
        return replace(self, controller={**self.controller, **settings})

    def with_settings(self, **entries) -> "TrainingRecord":
        """``entries`` laid over ``settings`` (a measure: ``support_penalty``, ...)."""
        return replace(self, settings={**self.settings, **entries})

    def deciding(self, reason: dict) -> "TrainingRecord":
        """One more setting decided, ``reason`` its record (setting, value, why)."""
        return self.with_settings(decided=[*self.settings["decided"], reason])

    def as_dict(self) -> dict:
        """The entries of the saved metrics."""
        out = {} if self.settings is None else {"settings": self.settings}
        out["controller"] = self.controller
        if self.label_smoothing_rule:
            out["label_smoothing_rule"] = self.label_smoothing_rule
        if self.selection is not None:
            out["selection"] = self.selection
        return out


class Recording:
    """The record while the belief trains: an ``inspect`` hook sets :attr:`record` to the
    record with its findings; calling the recording gives the metrics' entries
    (:meth:`TrainingRecord.as_dict`), as training merges them once the hooks ran."""

    def __init__(self, record: TrainingRecord):
        self.record = record

    def __call__(self) -> dict:
        return self.record.as_dict()
