"""The suite's command runner (tests/conftest.py ``run_aoc``, tests/cli_child.py): a command
forked from the preloaded server prints, fails and exits exactly as the console script in a
fresh interpreter, reads the store, working folder and stdin it is given, and leaves the
caller's state alone."""

import os

from tests.conftest import run_aoc

#: An environment entry outside AOC_*: run_aoc then starts a fresh interpreter (the reference).
FRESH = {"CLI_CHILD_FRESH_INTERPRETER": "1"}


def _both(*args, **kw):
    forked = run_aoc(*args, **kw)
    env = {**(kw.pop("env", None) or os.environ), **FRESH}
    return forked, run_aoc(*args, env=env, **kw)


def test_a_forked_command_prints_and_exits_as_a_fresh_interpreter(tmp_path):
    store = {**os.environ, "AOC_STORE": str(tmp_path / "store")}
    code, _out, err = run_aoc("collect", "maze", "--episodes", "3", "--name", "m", env=store)
    assert code == 0, err
    for args in (("--help",), ("info", "--help"), ("info", "nope", "--format", "json"),
                 ("info", "m", "--format", "csv"), ("train", "m", "--epochs", "0")):
        forked, fresh = _both(*args, env=store)
        assert forked == fresh, args
    assert forked[0] == 2 and forked[2].startswith("aoc: error:")   # a bad value, exit 2
    code, out, _err = run_aoc("info", "nope")
    assert code == 2 and out == ""


def test_a_forked_command_reads_its_working_folder_and_stdin(tmp_path):
    (tmp_path / "corpora").mkdir()
    code, out, err = run_aoc("collect", "maze", "--episodes", "2", "--name", "here",
                             "--format", "json", cwd=tmp_path)
    assert code == 0, err
    assert (tmp_path / "corpora" / "here").is_dir()     # the default store, in its folder
    before = os.getcwd()
    forked, fresh = _both("info", "here", "--format", "json", cwd=tmp_path, input="x\n")
    assert forked == fresh and forked[0] == 0 and "here" in forked[1]
    assert os.getcwd() == before
