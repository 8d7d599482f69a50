"""What every built-in task shares: the :class:`Task` record, and turning episodes into a corpus.

A task bundles a gymnasium environment (its evaluation settings: start, goal, horizon, success
test), its behaviour policies (``collect``) and a PNG renderer of trajectories. Success, where a
task defines it, is reported by the environment itself as ``info["success"]`` (a bool, present in
every step's info, final at the episode's last step); :meth:`Task.success` reads it.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Callable, Sequence

import numpy as np

from aoc_cli.errors import AocError, BadSetting, param
from aoc_cli.progress import Progress  # noqa: F401  (collection reports rows, or episodes, done)
from aoc_cli.store import CorpusData, episode_starts_from_lengths


@dataclass(frozen=True)
class Task:
    """A built-in task: its evaluation environment, behaviour policies and renderer.

    ``make(**kw)`` builds the evaluation environment (a plain ``gymnasium.Env``, time limit
    included); ``collect_fn(steps, episodes, seed, progress)`` runs the behaviour mix and
    returns ``(CorpusData, summary)``; ``trajectory(observations (T, d_o)) -> (T, 2)`` maps
    observations to the 2-d path that ``plot_trajectories`` draws.
    """

    name: str
    gym_id: str
    description: str
    horizon: int
    policies: tuple[str, ...]
    make_fn: Callable[..., Any]
    collect_fn: Callable[..., tuple[CorpusData, list[dict]]]
    plot_fn: Callable[..., None]
    trajectory_fn: Callable[[np.ndarray], np.ndarray]
    default_steps: int | None = None
    default_episodes: int | None = None
    start: tuple[float, ...] | None = None
    goal: tuple[float, ...] | None = None
    success_test: str | None = None
    extra: dict = field(default_factory=dict)
    #: The behaviours ``collect`` can run (``mix``: the task's policies; ``replay``: an agent
    #: that starts random and improves, aoc_cli/envs/replay.py).
    behaviours: tuple[str, ...] = ("mix",)

    @property
    def defines_success(self) -> bool:
        return self.success_test is not None

    def make(self, **kw):
        """The evaluation environment (gymnasium API, time limit ``horizon`` included)."""
        return self.make_fn(**kw)

    def success(self, info_or_episode) -> bool | None:
        """Whether an episode succeeded: pass the final step's info dict (or the list of an
        episode's info dicts). ``None`` when the task defines no success test."""
        if not self.defines_success:
            return None
        info = info_or_episode
        if isinstance(info, (list, tuple)):
            if not info:
                return False
            info = info[-1]
        if not isinstance(info, dict):
            raise AocError(f"task {self.name!r}: success() expects the final info dict, got "
                           f"{type(info).__name__}")
        return bool(info.get("success", False))

    def trajectory(self, observations: np.ndarray) -> np.ndarray:
        """Observations (T, d_o) -> the plotted path (T, 2)."""
        return self.trajectory_fn(np.asarray(observations))

    def plot_trajectories(self, paths: Sequence[np.ndarray], out_png, title: str | None = None,
                          labels: Sequence[str] | None = None) -> None:
        """Draw paths (each (T, 2), see :meth:`trajectory`) over the task's map into a PNG."""
        self.plot_fn(paths, out_png, title=title, labels=labels)

    def describe(self) -> dict:
        """One row of ``aoc collect --list``."""
        return {
            "name": self.name,
            "gym_id": self.gym_id,
            "horizon": self.horizon,
            "default_steps": self.default_steps,
            "default_episodes": self.default_episodes,
            "policies": ", ".join(self.policies),
            "success": self.success_test or "none (returns)",
        }


@dataclass
class Episode:
    """One logged episode: observations (T, d_o), actions (T, d_a), rewards (T,); whether it
    ended in a terminal state; its tags (tag name -> label); ``success`` where defined."""

    observations: np.ndarray
    actions: np.ndarray
    rewards: np.ndarray
    terminal: bool
    tags: dict[str, str]
    success: bool | None = None
    goal_reached: bool | None = None
    #: False for an episode cut short by the row budget (left out of the return statistics).
    complete: bool = True

    def __len__(self) -> int:
        return len(self.rewards)

    def cut(self, n: int) -> "Episode":
        """The first ``n`` rows (a truncated episode: no longer terminal)."""
        return Episode(self.observations[:n], self.actions[:n], self.rewards[:n], False,
                       self.tags, None, None, complete=False)


def collected_task(corpus) -> str:
    """The built-in task a stored corpus was collected from, as its manifest's sources record
    it (``aoc collect`` writes ``{"kind": "collect", "task": ...}``); ``""`` for a corpus
    ingested from a file or appended from several tasks. For what a page shows only (the units
    of a task's observations): no setting is ever decided by it (aoc_cli.training.evidence)."""
    sources = (getattr(corpus, "manifest", None) or {}).get("sources", [])
    tasks = {src.get("task") or "" for src in sources if src.get("kind") == "collect"}
    if len(tasks) != 1 or any(src.get("kind") != "collect" for src in sources):
        return ""
    return tasks.pop()


def budget(steps: int | None, episodes: int | None, default_steps: int | None,
           default_episodes: int | None) -> tuple[int | None, int | None]:
    """Resolve ``steps`` / ``episodes`` against the task's defaults (exactly one is set)."""
    if steps is not None and episodes is not None:
        raise AocError(f"give {param('steps')} or {param('episodes')}, not both")
    for name, value in (("steps", steps), ("episodes", episodes)):
        if value is not None and (isinstance(value, bool) or int(value) != value or value <= 0):
            raise BadSetting(name, value, f"{param(name)} must be a positive integer, got {value}")
    if steps is None and episodes is None:
        steps, episodes = default_steps, (None if default_steps else default_episodes)
    return (None if steps is None else int(steps)), (None if episodes is None else int(episodes))


def to_corpus(episodes: Sequence[Episode], tag_labels: dict[str, Sequence[str]],
              observation_space: dict, action_space: dict, source: dict,
              steps: int | None = None) -> CorpusData:
    """Concatenate episodes into a corpus; with ``steps``, keep exactly that many rows (the
    last kept episode cut short and marked truncated).

    Episodes that are not terminal are marked truncated at their last row (time limit or cut).
    Tag codes index ``tag_labels[name]`` (a fixed order, so codes do not depend on the data).
    """
    episodes = list(episodes)
    if steps is not None:
        kept, total = [], 0
        for ep in episodes:
            if total >= steps:
                break
            take = min(len(ep), steps - total)
            kept.append(ep if take == len(ep) else ep.cut(take))
            total += take
        if total < steps:
            raise AocError(f"internal: collected {total} rows, fewer than the {steps} asked")
        episodes = kept
    lengths = np.array([len(ep) for ep in episodes], dtype=np.int64)
    starts = episode_starts_from_lengths(lengths)
    n = int(starts[-1])
    terminals = np.zeros(n, dtype=bool)
    truncations = np.zeros(n, dtype=bool)
    last = starts[1:] - 1
    is_terminal = np.array([ep.terminal for ep in episodes], dtype=bool)
    terminals[last[is_terminal]] = True
    truncations[last[~is_terminal]] = True
    tags = {}
    for tag, labels in tag_labels.items():
        labels = list(labels)
        codes = np.array([labels.index(ep.tags[tag]) for ep in episodes], dtype=np.int32)
        tags[tag] = (np.repeat(codes, lengths), labels)
    return CorpusData(
        observations=np.concatenate([ep.observations for ep in episodes]).astype(np.float32),
        actions=np.concatenate([ep.actions for ep in episodes]).astype(np.float32),
        rewards=np.concatenate([ep.rewards for ep in episodes]).astype(np.float64),
        terminals=terminals,
        truncations=truncations,
        episode_starts=starts,
        observation_space=observation_space,
        action_space=action_space,
        tags=tags,
        source=source,
    )


def summarise(episodes: Sequence[Episode], tag_labels: dict[str, Sequence[str]],
              kept_rows: int | None = None) -> list[dict]:
    """Per-policy summary: episodes, rows, mean and std of the return, success rate.

    One record per combination of the tags in ``tag_labels`` (tag -> labels, in display order).
    Returns and rates are over the complete episodes (an episode cut short by ``--steps`` counts
    in ``rows`` and ``episodes`` but not in the return statistics). With ``kept_rows``, only the
    first ``kept_rows`` rows (as :func:`to_corpus` keeps them) are summarised.
    """
    group_by = list(tag_labels)
    groups: dict[tuple, dict] = {}
    total = 0
    for ep in episodes:
        if kept_rows is not None and total >= kept_rows:
            break
        take = len(ep) if kept_rows is None else min(len(ep), kept_rows - total)
        total += take
        key = tuple(ep.tags[g] for g in group_by)
        g = groups.setdefault(key, {"episodes": 0, "rows": 0, "returns": [], "success": [],
                                    "goal": []})
        g["episodes"] += 1
        g["rows"] += take
        if ep.complete and take == len(ep):
            g["returns"].append(float(np.sum(ep.rewards)))
            if ep.success is not None:
                g["success"].append(bool(ep.success))
            if ep.goal_reached is not None:
                g["goal"].append(bool(ep.goal_reached))
    out = []
    for key in sorted(groups, key=lambda k: [list(tag_labels[g]).index(v)
                                             for g, v in zip(group_by, k)]):
        g = groups[key]
        rec: dict[str, Any] = dict(zip(group_by, key))
        rets = np.array(g["returns"])
        rec.update(episodes=g["episodes"], rows=g["rows"],
                   mean_return=float(rets.mean()) if len(rets) else None,
                   std_return=float(rets.std()) if len(rets) else None)
        if g["goal"]:
            rec["own_goal_rate"] = float(np.mean(g["goal"]))
        if g["success"]:
            rec["success_rate"] = float(np.mean(g["success"]))
        out.append(rec)
    return out
