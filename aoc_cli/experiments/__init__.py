"""The paper's experiments end to end (`aoc bench`): collect, train, index, roll out AOC and
the baselines, and write results.csv, summary.md, summary.json and PNG plots.

>>> from aoc_cli.experiments import EXPERIMENTS, run_experiment, expected_seconds
>>> sorted(EXPERIMENTS)[:3]
['epsilon', 'k', 'lunar']
"""

from aoc_cli.baselines.sepsis_policies import log_model, state_policy  # the sepsis bench's
from aoc_cli.experiments.beliefs import model_config
from aoc_cli.experiments.prepare import Artefacts
from aoc_cli.experiments.runner import EXPERIMENTS, ORDER, expected_seconds, run_experiment
from aoc_cli.experiments.ward import history_features

__all__ = ["EXPERIMENTS", "ORDER", "Artefacts", "expected_seconds", "history_features",
           "log_model", "model_config", "run_experiment", "state_policy"]
