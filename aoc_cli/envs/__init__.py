"""Built-in tasks: gymnasium environments with their behaviour policies and evaluation settings.

>>> from aoc_cli.envs import TASKS, collect, make_env
>>> env = make_env("maze")                       # the evaluation env: (0, 0) -> (16, 0), 100 steps
>>> data, summary = collect("two-gates", episodes=8, seed=0)
>>> data.n_episodes, sorted(data.tags)
(8, ['policy'])

Importing this package registers the gymnasium ids ``aoc/PendulumHet-v0``,
``aoc/PendulumHetUpright-v0``, ``aoc/Maze-v0`` and ``aoc/TwoGates-v0`` (without importing it
first: ``gymnasium.make("aoc_cli.envs:aoc/Maze-v0")``). ``lunar`` is gymnasium's own
``LunarLanderContinuous-v3``.

Success: where a task defines it (maze, two-gates, lunar), its evaluation environment puts a bool
``info["success"]`` in every step's info; the value at the episode's last step is the outcome.
pendulum-het defines none (compare returns).
"""

from __future__ import annotations

import gymnasium

from aoc_cli.envs.base import Episode, Progress, Task, collected_task
from aoc_cli.errors import AocError, BadSetting, call, param
from aoc_cli.store import CorpusData

_IDS = {
    "aoc/PendulumHet-v0": ("aoc_cli.envs.pendulum_het:PendulumHetEnv", 200, {}),
    "aoc/PendulumHetUpright-v0": ("aoc_cli.envs.pendulum_het:PendulumHetEnv", 200,
                                  {"upright": True}),
    "aoc/Maze-v0": ("aoc_cli.envs.maze:MazeEnv", 100, {"world": "maze"}),
    "aoc/TwoGates-v0": ("aoc_cli.envs.maze:MazeEnv", 32, {"world": "two-gates"}),
    "aoc/Ward-v0": ("aoc_cli.envs.ward:WardEnv", 12, {}),
    "aoc/ICUSepsis-v0": ("aoc_cli.envs.icu_sepsis:make_sepsis_env", 500, {"strategy": "mean"}),
    "aoc/ICUSepsisTerminate-v0": ("aoc_cli.envs.icu_sepsis:make_sepsis_env", 500,
                                  {"strategy": "terminate"}),
    "aoc/ICUCohort-v0": ("aoc_cli.envs.icu_cohort:CohortEnv", 500, {"strategy": "mean"}),
}
for _id, (_entry, _steps, _kwargs) in _IDS.items():
    if _id not in gymnasium.registry:
        gymnasium.register(id=_id, entry_point=_entry, max_episode_steps=_steps,
                           kwargs=_kwargs)

from aoc_cli.envs import (icu_cohort, icu_sepsis, lunar, maze, pendulum_het,  # noqa: E402
                         ward)  # (after registration)

#: name -> Task, in the order ``aoc collect --list`` shows them.
TASKS: dict[str, Task] = {t.name: t for mod in (pendulum_het, maze, lunar, ward,
                                                      icu_sepsis, icu_cohort)
                         for t in mod.TASKS}


def get_task(name: str) -> Task:
    """The built-in task ``name``; unknown -> AocError listing the tasks."""
    if name not in TASKS:
        raise BadSetting("task", name, f"unknown task {name!r}: use one of "
                         f"{', '.join(TASKS)} (see `{call('collect', list=True)}`)")
    return TASKS[name]


def task_settings(name: str) -> tuple[str, dict[str, float]]:
    """``TASK:key=value,key=value`` -> (TASK, {key: float}) for a built-in task that takes
    settings (``icu-cohort:noise=1.0,gap=0.15``); a name without ``:`` -> (name, {}). A key
    the task does not know, or a value that is not a number, is an AocError naming it and the
    known keys."""
    base, sep, rest = name.partition(":")
    if not sep or base not in TASKS:
        return name, {}
    known = TASKS[base].extra.get("settings") or {}
    if not known:
        raise BadSetting("env", name, f"{param('env')}: task {base!r} takes no settings (got "
                         f"{rest!r}): use {base!r} alone")
    out: dict[str, float] = {}
    for item in rest.split(","):
        key, eq, value = (part.strip() for part in item.partition("="))
        if key not in known or not eq:
            raise BadSetting("env", name, f"{param('env')} {name!r}: {item.strip()!r} is not a "
                             "setting of "
                             f"{base!r}: use {base}:KEY=VALUE,... with KEY among "
                             f"{', '.join(known)} (defaults "
                             f"{', '.join(f'{k}={v}' for k, v in known.items())})")
        try:
            out[key] = float(value)
        except ValueError:
            raise BadSetting("env", name, f"{param('env')} {name!r}: {key}={value!r} is not a "
                             "number "
                             f"(settings of {base!r}: {', '.join(known)})") from None
    return base, out


def make_env(name_or_gym_id: str, **kw) -> gymnasium.Env:
    """A built-in task's evaluation environment (``TASK:key=value,...``: with those settings,
    :func:`task_settings`), or any registered gymnasium id."""
    base, settings = task_settings(name_or_gym_id)
    if base in TASKS:
        return TASKS[base].make(**settings, **kw)
    try:
        return gymnasium.make(name_or_gym_id, **kw)
    except gymnasium.error.DependencyNotInstalled as err:
        raise AocError(f"gymnasium environment {name_or_gym_id!r} needs a package that is "
                       f"not installed: {str(err).splitlines()[0]}") from err
    except (gymnasium.error.Error, ModuleNotFoundError) as err:
        raise AocError(f"unknown environment {name_or_gym_id!r}: use a built-in task "
                       f"({', '.join(TASKS)}) or a registered gymnasium id such as "
                       f"Pendulum-v1 ({str(err).splitlines()[0]})") from err


def collect(task: str, steps: int | None = None, episodes: int | None = None, seed: int = 0,
            progress: Progress | None = None, behaviour: str = "mix",
            policy: str | None = None) -> tuple[CorpusData, list[dict]]:
    """Run ``task``'s behaviour mix for exactly ``steps`` rows (or ``episodes`` episodes; neither:
    the task's default) and return the corpus data and a per-policy summary (episodes, rows,
    mean/std return, success rate where defined). Same seed, same arrays, bit for bit.
    ``behaviour="replay"`` (pendulum-het, pendulum-het-upright, lunar): the data of an agent
    that starts random and improves (aoc_cli/envs/replay.py).

    ``policy`` (icu-sepsis): the one behaviour policy to log (default the task's first).

    ``progress(done, total)`` is called as rows (or episodes) are collected.
    """
    t = get_task(task)
    if behaviour not in t.behaviours:
        raise AocError(f"task {task!r} has no behaviour {behaviour!r}: use "
                       f"{', '.join(t.behaviours)}")
    extra = {} if behaviour == "mix" else {"behaviour": behaviour}
    if policy is not None:
        if not t.extra.get("choose_policy"):
            raise BadSetting("policy", policy, f"task {task!r} logs its own mix of policies: "
                             f"{param('policy')} is for tasks with one behaviour at a time "
                             "(icu-sepsis)")
        if policy not in t.policies:
            raise AocError(f"task {task!r} has no policy {policy!r}: use "
                           f"{' or '.join(t.policies)}")
        extra["policy"] = policy
    data, summary = t.collect_fn(steps=steps, episodes=episodes, seed=int(seed),
                                 progress=progress, **extra)
    return data.validate(), summary


#: icu-sepsis's tables (the MDP, its observations, the clinicians' policy) and pendulum-het's
#: swing-up controller: the references a notes script values a policy or a log against.
sepsis_tables = icu_sepsis.tables
swingup_action = pendulum_het.swingup_action

__all__ = ["TASKS", "Episode", "Task", "collect", "collected_task", "get_task", "make_env",
           "sepsis_tables", "swingup_action", "task_settings"]
