"""``aoc info`` and ``aoc ls`` through the real CLI."""

import json

import numpy as np
import pytest

from tests.cli.test_ingest import run_in_process
from tests.formats.sources import flat_arrays, write_d4rl


@pytest.fixture
def aoc(capsys):
    """The real entry point in this process (see tests/cli/test_ingest.py::run_in_process)."""
    return lambda *args: run_in_process(capsys, *args)

REQUIRED = {"name", "rows", "episodes", "observation_dim", "action_dim", "discrete",
            "has_rewards", "return_mean", "return_std", "tags"}


def ingest(aoc, tmp_path, name, **kw):
    arrays, exp = flat_arrays(**kw)
    path = write_d4rl(tmp_path / f"{name}.hdf5", arrays,
                      infos={"policy": np.where(np.arange(len(arrays["rewards"])) < 150,
                                                b"expert", b"noisy")})
    code, _, err = aoc("ingest", str(path), "--name", name, "--tag-column", "policy")
    assert code == 0, err
    return exp


def test_info_json_has_the_issue_keys_and_true_statistics(store, aoc, tmp_path):
    exp = ingest(aoc, tmp_path, "hopper")
    code, out, err = aoc("info", "hopper", "--format", "json")
    assert code == 0, err
    info = json.loads(out)
    assert REQUIRED <= set(info)
    assert (info["name"], info["rows"], info["episodes"]) == ("hopper", 400, 4)
    assert (info["observation_dim"], info["action_dim"]) == (5, 2)
    assert info["discrete"] is False and info["has_rewards"] is True
    np.testing.assert_allclose(info["return_mean"], exp.returns.mean())
    np.testing.assert_allclose(info["return_std"], exp.returns.std())
    np.testing.assert_allclose(info["return_max"], exp.returns.max())
    assert info["tags"] == {"policy": {"expert": 150, "noisy": 250}}
    assert info["built"] == []


def test_info_reports_models_ok_stale_and_without_config(store, aoc, tmp_path):
    ingest(aoc, tmp_path, "hopper")
    corpus_hash = json.loads((store / "hopper" / "manifest.json").read_text())["content_hash"]
    models = store / "hopper" / "models"
    for mid, cfg in (("a", {"corpus_hash": corpus_hash, "mode": "value"}),
                     ("b", {"corpus_hash": "0" * 32}), ("c", None)):
        (models / mid).mkdir(parents=True)
        if cfg is not None:
            (models / mid / "config.json").write_text(json.dumps(cfg))
    code, out, err = aoc("info", "hopper", "-f", "json")
    assert code == 0, err
    built = {m["id"]: m for m in json.loads(out)["built"]}
    assert {k: m["status"] for k, m in built.items()} == {"a": "ok", "b": "stale",
                                                          "c": "unknown"}
    assert built["a"]["mode"] == "value" and built["a"]["files"] == ["config.json"]
    code, out, _ = aoc("info", "hopper", "-f", "table")
    assert "stale" in out and "expert" in out and "400" in out


def test_info_of_unknown_corpus_is_one_line_exit_2(store, aoc):
    code, out, err = aoc("info", "nope")
    assert code == 2 and out == ""
    assert len(err.strip().splitlines()) == 1 and "aoc ingest" in err


def test_ls_lists_every_corpus(store, aoc, tmp_path):
    code, out, _ = aoc("ls", "-f", "json")
    assert code == 0 and json.loads(out) == []
    ingest(aoc, tmp_path, "a")
    ingest(aoc, tmp_path, "b", n=300, ends=((99, "t"),))
    code, out, err = aoc("ls", "--format", "json")
    assert code == 0, err
    rows = json.loads(out)
    assert [(r["name"], r["rows"], r["episodes"]) for r in rows] == [("a", 400, 4), ("b", 300, 2)]
    code, out, _ = aoc("ls", "-f", "csv")
    assert out.splitlines()[0].startswith("name,rows,episodes")
    assert out.splitlines()[2].startswith("b,300,2")


def test_info_table_names_where_each_corpus_came_from(store, aoc, tmp_path):
    ingest(aoc, tmp_path, "hopper")
    code, out, err = aoc("collect", "maze", "--episodes", "8", "--seed", "3", "--name", "maze")
    assert code == 0, err
    code, out, err = aoc("info", "hopper", "--format", "table")
    assert code == 0, err
    assert f"d4rl {tmp_path / 'hopper.hdf5'}" in out    # tables are 200 wide off a terminal
    code, out, err = aoc("info", "maze", "--format", "table")
    assert code == 0, err
    assert "collect maze (seed 3, 8 episodes; pi1, pi2, pi3, pi4)" in out
