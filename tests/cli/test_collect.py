import json

import numpy as np

from aoc_cli.store import Store


def test_collect_writes_a_corpus_and_prints_the_policy_summary(aoc, store):
    code, out, err = aoc("collect", "pendulum-het", "--steps", "2000", "--name", "ph",
                         "--seed", "2", "--format", "json")
    assert code == 0, err
    summary = json.loads(out)
    assert {(r["system"], r["policy"]) for r in summary} >= {("normal", "random"),
                                                           ("converse", "swingup-noise0")}
    assert sum(r["rows"] for r in summary) == 2000
    corpus = Store(store).corpus("ph")
    assert corpus.n_rows == 2000 and set(corpus.manifest["tags"]) == {"system", "policy"}
    assert corpus.manifest["sources"][0]["task"] == "pendulum-het"
    assert "wrote corpus 'ph'" in err and "2000 rows" in err


def test_same_seed_gives_identical_files_and_hash(aoc, store):
    for name in ("a", "b"):
        code, _out, err = aoc("collect", "two-gates", "--episodes", "10", "--name", name,
                              "--seed", "4", "--format", "csv")
        assert code == 0, err
    a, b = Store(store).corpus("a"), Store(store).corpus("b")
    assert a.hash == b.hash
    assert (a.path / "corpus.h5").read_bytes() == (b.path / "corpus.h5").read_bytes()
    np.testing.assert_array_equal(a.tag("policy")[0], b.tag("policy")[0])


def test_list_shows_every_task_with_its_defaults(aoc, store):
    code, out, err = aoc("collect", "--list", "--format", "json")
    assert code == 0, err
    rows = {r["name"]: r for r in json.loads(out)}
    assert list(rows) == ["pendulum-het", "pendulum-het-upright", "maze", "two-gates", "lunar",
                          "ward", "icu-sepsis", "icu-sepsis-terminate", "icu-cohort"]
    assert rows["maze"]["default_episodes"] == 1000 and rows["maze"]["horizon"] == 100
    assert rows["pendulum-het"]["default_steps"] == 100000
    assert rows["two-gates"]["policies"] == "lower-gate, upper-gate"
    assert rows["lunar"]["gym_id"] == "LunarLanderContinuous-v3"


def test_bad_input_is_one_line_and_exit_2(aoc, store):
    code, _out, err = aoc("collect", "maze", "--episodes", "4", "--name", "m")
    assert code == 0, err
    cases = [
        (["collect", "maze", "--episodes", "4", "--name", "m"], "already exists"),
        (["collect", "mazes", "--name", "x"], "unknown task 'mazes'"),
        (["collect", "maze", "--steps", "0", "--name", "x"], "--steps must be a positive"),
        (["collect", "lunar", "--steps", "-3", "--name", "x"], "--steps must be a positive"),
        (["collect", "maze", "--name", "../x"], "invalid corpus name"),
        (["collect", "maze"], "--name NAME"),
        (["collect", "icu-sepsis", "--episodes", "0", "--name", "x"],
         "--episodes must be a positive"),
        (["collect", "icu-sepsis", "--policy", "surgeons", "--name", "x"],
         "--policy 'surgeons'"),
        (["collect", "maze", "--policy", "random", "--name", "x"], "--policy is for icu-sepsis"),
    ]
    for args, needle in cases:
        code, out, err = aoc(*args)
        assert code == 2, (args, err)
        lines = err.strip().splitlines()
        assert len(lines) == 1 and needle in lines[0] and "Traceback" not in err, (args, err)
        assert out == ""
    assert not Store(store).exists("x")


def test_overwrite_replaces_the_corpus(aoc, store):
    assert aoc("collect", "maze", "--episodes", "4", "--name", "m")[0] == 0
    code, _out, err = aoc("collect", "maze", "--episodes", "8", "--name", "m", "--overwrite")
    assert code == 0, err
    assert Store(store).corpus("m").n_episodes == 8
