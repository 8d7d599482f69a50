"""Each built-in task's own training settings (``Task.training``), under the user's flags.

``aoc train`` on a corpus collected from a built-in task (its manifest's sources name the task:
:func:`aoc_cli.envs.collected_task`) starts from the settings measured to work on that task
instead of the paper's: a flag the user gives wins, then the task's setting, then the paper's
(:class:`~aoc_cli.belief.config.BeliefConfig`'s default); ``--paper`` skips the task's settings.
A corpus ingested from a file (or appended from several sources) has no task and keeps the
generic defaults. The settings taken from the task go to the output and to the model's config
(``metrics.task_settings``), as the controller's do for ``aoc rollout --env TASK``
(``Task.controller``).

The settings are keyed by the model they were measured with: ``all`` for every model of the
task, else the value-mode belief kind (``value``, ``critic``, ``reward``, ``dynamics``) or
``imitation``; e.g. pendulum-het-upright's gamma 0.9 was measured with the value belief only,
so ``--belief critic`` there keeps the critic's own default.

>>> from aoc_cli.envs import TASKS
>>> TASKS["pendulum-het-upright"].training
{'value': {'gamma': 0.9}}
>>> resolve({"gamma": None, "hidden": 64}, {"value": {"gamma": 0.9, "hidden": 128}})
({'gamma': 0.9, 'hidden': 64}, {'gamma': 0.9})
"""

from __future__ import annotations

from aoc_cli.envs import TASKS, collected_task
from aoc_cli.errors import AocError

#: The settings a task may set: each is a flag of ``aoc train`` that is None when not given.
FIELDS = ("mode", "belief", "gamma", "value", "dynamics_weight", "history_length", "hidden",
          "weight_decay")
#: The keys of ``Task.training``: every model, or the model a setting was measured with.
KEYS = ("all", "value", "critic", "reward", "dynamics", "imitation")


def for_corpus(corpus, paper: bool = False) -> tuple[str, dict]:
    """(the built-in task ``corpus`` was collected from or ``""``, that task's training
    settings, keyed as ``Task.training``); no settings with ``paper`` or without a task."""
    task = collected_task(corpus)
    if paper or task not in TASKS:
        return task, {}
    settings = {key: dict(values) for key, values in TASKS[task].training.items()}
    unknown = sorted(set(settings) - set(KEYS)) + sorted(
        {k for values in settings.values() for k in values} - set(FIELDS))
    if unknown:
        raise AocError(f"internal: task {task!r} has training settings that train cannot "
                       f"take: {', '.join(unknown)}")
    return task, settings


def model_kind(given: dict) -> str:
    """The key of ``Task.training`` that a model of these settings falls under."""
    if (given.get("mode") or "value") == "imitation":
        return "imitation"
    if given.get("belief") in (None, "value") and (given.get("dynamics_weight") or 0) > 0:
        return "dynamics"
    return given.get("belief") or "value"


def resolve(given: dict, settings: dict) -> tuple[dict, dict]:
    """``given`` (setting -> the user's value, None when not given) with the task's
    ``settings`` (keyed as ``Task.training``) filled in where the user gave nothing: first
    ``all``, then those of the model so chosen (:func:`model_kind`); and the settings taken."""
    used = {k: v for k, v in settings.get("all", {}).items() if given.get(k) is None}
    given = {**given, **used}
    more = {k: v for k, v in settings.get(model_kind(given), {}).items()
            if given.get(k) is None}
    return {**given, **more}, {**used, **more}


def describe(task: str, used: dict) -> str:
    """One line for ``aoc train``'s output: the settings taken from the task."""
    flags = ", ".join(f"--{k.replace('_', '-')} {v}" for k, v in used.items())
    return (f"{task}'s own training settings: {flags} (measured to work on this task; give "
            "the flag to override, --paper for the paper's)")
