"""The paper's experiments end to end (`aoc bench`): collect, train, index, roll out AOC and
the baselines, and write results.csv, summary.md, summary.json and PNG plots.

>>> from aoc_cli.experiments import EXPERIMENTS, run_experiment, expected_seconds
>>> sorted(EXPERIMENTS)[:3]
['epsilon', 'k', 'lunar']
"""

from aoc_cli.experiments.runner import EXPERIMENTS, ORDER, expected_seconds, run_experiment

__all__ = ["EXPERIMENTS", "ORDER", "expected_seconds", "run_experiment"]
