"""What ``aoc train`` decides, above the belief, the OPE and the controller: the belief fit's
driver (:func:`train_corpus`, fit.py), the settings decided from the log's evidence
(evidence.py; the controller's epsilon measured on held-out episodes, epsilon_rule.py), the
settings chosen by validation on small logs (tuning.py) and the controller chosen on held-out
episodes by FQE (controller_selection.py). What it decided is one record, saved with the
model's metrics (:class:`TrainingRecord`, record.py).

>>> from aoc_cli.training import train_corpus
>>> trained = train_corpus(corpus, "default")                    # doctest: +SKIP

Names are imported lazily (PEP 562), so that reading the rules (as ``aoc train --help`` does)
imports no torch.
"""

from __future__ import annotations

from aoc_cli.lazy import exports

_WHERE = {
    "Evidence": "evidence",
    "Trained": "fit",
    "TrainingRecord": "record",
    "abc_scores": "tuning",
    "check_settings": "fit",
    "train_corpus": "fit",
}

__all__ = sorted(_WHERE)


__getattr__, __dir__ = exports(__name__, _WHERE)
