"""One progress protocol (aoc_cli.progress): library work reports ``progress(done, total,
label)`` and never loads a terminal library; the command line draws it with rich."""

import subprocess
import sys

from aoc_cli.baselines import make_baseline
from aoc_cli.control import rollout
from aoc_cli.control.episodes import action_space_of
from aoc_cli.envs import collect, make_env
from aoc_cli.progress import stage, tracked
from aoc_cli.control import model_free_session
from aoc_cli.store import Store


def test_tracked_reports_each_item_done_of_the_total():
    seen = []
    assert list(tracked("abc", lambda *a: seen.append(a), "letters", 3)) == ["a", "b", "c"]
    assert seen == [(0, 3, "letters"), (1, 3, "letters"), (2, 3, "letters"), (3, 3, "letters")]
    assert list(tracked(range(2), None, "silent")) == [0, 1]


def test_a_stage_labels_the_reports_of_its_work():
    seen = []
    part = stage(lambda *a: seen.append(a), "collect maze", 10)
    part(4, 10)
    part(5, None, "episode 2")
    assert seen == [(0, 10, "collect maze"), (4, 10, "collect maze"),
                    (5, None, "collect maze: episode 2")]
    assert stage(None, "nothing") is None


def test_collection_and_rollout_report_through_the_protocol(tmp_path):
    seen = []
    data, _ = collect("maze", episodes=8, seed=0, progress=lambda *a: seen.append(a))
    assert seen and seen[-1][:2] == (8, 8)
    corpus = Store(tmp_path).write("maze", data)
    env = make_env("maze")
    session = model_free_session(corpus, action_space_of(env))
    seen.clear()
    rollout(session, env, 3, policy=make_baseline("zero", session, env),
            progress=lambda *a: seen.append(a))
    assert [s[:2] for s in seen] == [(0, 3), (1, 3), (2, 3), (3, 3)]
    assert all(s[2].startswith("rollout") for s in seen)


def test_the_library_never_loads_a_terminal_library():
    code = ("import sys, aoc_cli.index.build, aoc_cli.control, aoc_cli.belief.train, "
            "aoc_cli.belief.stream, aoc_cli.formats, aoc_cli.envs, aoc_cli.baselines, "
            "aoc_cli.decompose, aoc_cli.index.search, aoc_cli.store, aoc_cli.progress, aoc_cli.threads; "
            "print(sorted(m for m in sys.modules if m.split('.')[0] in ('rich', 'typer')))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True)
    assert out.stdout.strip() == "[]"
