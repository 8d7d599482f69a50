"""Evaluation of a controller on a held-out log: every step decided as the controller would
and scored against what was logged (docs/design.md, "Evaluation").

- :mod:`aoc_cli.evaluation.context`: what scoring needs, built once (candidates, targets);
- :mod:`aoc_cli.evaluation.score`: the scoring of episodes, in chunks, and its summary;
- :mod:`aoc_cli.evaluation.ray`: the same chunks as Ray tasks;
- :mod:`aoc_cli.evaluation.step_scores`: a chunk's per-step results (:class:`StepScores`);
- :mod:`aoc_cli.evaluation.records`: one JSON-ready record per scored step.

The controller chosen on a model's held-out episodes by FQE is training's
(:mod:`aoc_cli.training.controller_selection`).
"""
