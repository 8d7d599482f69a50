"""The library's public API (aoc_cli/api.py), called as a library user would: a store folder
passed as ``store=``, results read from what each entry returns (the commands print the same
data: tests/cli/)."""

from __future__ import annotations

import importlib.util
import json
import subprocess
import sys

import numpy as np
import pytest

import aoc_cli
from aoc_cli import api
from aoc_cli.errors import AocError, BadSetting, ModelExists
from aoc_cli.store import Store


def test_importing_aoc_cli_and_aoc_help_import_no_torch():
    probe = ("import sys\nimport aoc_cli\nassert 'aoc_cli.api' not in sys.modules\n"
             "from aoc_cli.cli.app import main\ntry:\n    main(['--help'])\nexcept SystemExit:\n"
             "    pass\nprint(sorted(m for m in ('torch', 'faiss', 'aoc_cli.api') "
             "if m in sys.modules))\n"
             "aoc_cli.info, aoc_cli.verify, aoc_cli.ingest, aoc_cli.export\n"
             "print(sorted(m for m in ('torch', 'faiss', 'matplotlib', 'gymnasium') "
             "if m in sys.modules))")
    out = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True,
                         check=True).stdout
    # aoc --help loads no entry; the store's entries (aoc info, ls, verify, ingest, export)
    # load neither torch, FAISS, matplotlib nor the environments
    assert out.strip().splitlines()[-2:] == ["[]", "[]"]


def test_the_package_re_exports_every_entry_of_the_api():
    for name in aoc_cli.API:
        assert getattr(aoc_cli, name) is getattr(api, name)
    assert set(aoc_cli.API) <= set(dir(aoc_cli))
    with pytest.raises(AttributeError):
        aoc_cli.no_such_entry  # noqa: B018


def test_importing_the_api_modules_first_hides_no_entry():
    """A submodule import binds its name in the package: were a module named after an entry,
    ``import aoc_cli.api.<that module>`` before the entry's first use would turn the entry into
    a module. Checked in a fresh interpreter, every module imported before any entry is used."""
    probe = ("import importlib, pkgutil, types\nimport aoc_cli.api as api\n"
             "for m in pkgutil.iter_modules(api.__path__):\n"
             "    importlib.import_module('aoc_cli.api.' + m.name)\n"
             "print(sorted(n for n in api.__all__ if isinstance(getattr(api, n), types.ModuleType)"
             " or not (callable(getattr(api, n)))))")
    out = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True,
                         check=True).stdout
    assert out.strip() == "[]"


def test_no_module_of_the_package_is_named_after_an_entry():
    """The same one level up: ``aoc_cli.<entry>`` is the API's entry, so no module or package of
    aoc_cli takes an entry's name (a package ``aoc_cli/explain/``, once imported, would make
    ``aoc_cli.explain`` that package)."""
    assert [n for n in aoc_cli.API if importlib.util.find_spec(f"aoc_cli.{n}")] == []


def test_collect_writes_the_corpus_the_command_writes(tmp_path, aoc):
    done = api.collect("two-gates", "g", store=tmp_path, episodes=10, seed=4)
    assert done.corpus.n_episodes == 10 and done.task == "two-gates"
    assert sum(r["episodes"] for r in done.summary) == 10
    code, _out, err = aoc("--store", str(tmp_path / "cli"), "collect", "two-gates",
                          "--episodes", "10", "--seed", "4", "--name", "g")
    assert code == 0, err
    assert Store(tmp_path / "cli").corpus("g").hash == done.corpus.hash
    with pytest.raises(AocError, match="already exists"):
        api.collect("two-gates", "g", store=tmp_path, episodes=10)
    with pytest.raises(BadSetting, match="give steps or episodes, not both"):
        api.collect("two-gates", "h", store=tmp_path, episodes=10, steps=100)
    assert not Store(tmp_path).exists("h")


def test_info_corpora_and_export_ingest_round_trip(tmp_path):
    store = tmp_path / "store"
    api.collect("two-gates", "g", store=store, episodes=8, seed=2)
    assert api.info("g", store=store)["episodes"] == 8
    root, rows = api.corpora(store=store)
    assert root == store and [r["name"] for r in rows] == ["g"]
    with pytest.raises(AocError, match="inside the corpus store"):
        api.export("g", "d4rl", store / "g.h5", store=store)
    out = tmp_path / "g.h5"
    exported = api.export("g", "d4rl", out, store=store)
    assert exported.rows == Store(store).corpus("g").n_rows and out.is_file()
    back = api.ingest(out, "back", store=store, options={"drop_nonfinite": False})
    assert back.rows == exported.rows and back.format == "d4rl"
    assert Store(store).corpus("back").hash == Store(store).corpus("g").hash


def test_verify_reports_a_damaged_corpus_and_names_what_rebuilds_it(tmp_path):
    api.collect("two-gates", "g", store=tmp_path, episodes=8, seed=2)
    intact = api.verify(store=tmp_path)
    assert intact.corpora == ["g"] and intact.files > 0 and intact.failure() is None
    h5 = tmp_path / "g" / "corpus.h5"
    data = bytearray(h5.read_bytes())
    data[len(data) // 2] ^= 0xFF
    h5.write_bytes(bytes(data))
    damaged = api.verify(["g"], store=tmp_path)
    assert damaged.bad and all(r["corpus"] == "g" for r in damaged.bad)
    assert "re-ingest or re-collect" in damaged.failure()
    assert damaged.bad[0]["file"] in damaged.failure()


@pytest.fixture(scope="module")
def trained(tmp_path_factory):
    """A two-gates corpus with a small model and its index, all through the API."""
    store = tmp_path_factory.mktemp("api") / "store"
    api.collect("two-gates", "g", store=store, episodes=40, seed=1)
    done = api.train("g", store=store, max_epochs=3, threads=1, hidden=16)
    built = api.build_index("g", store=store)
    return store, done, built


def test_train_returns_the_metrics_it_saved_and_refuses_a_second_model_of_that_id(trained):
    store, done, built = trained
    assert done.metrics["mode"] == "value" and done.config.hidden == 16
    assert done.metrics["epochs"] <= 3 and "val_r2" in done.metrics
    saved = json.loads((Store(store).corpus("g").models_dir / "default" / "config.json")
                       .read_text())
    assert saved["metrics"]["val_r2"] == done.metrics["val_r2"]
    assert built.summary()["rows"] == Store(store).corpus("g").n_rows
    assert built.summary()["model"] == "default"
    with pytest.raises(ModelExists):
        api.train("g", store=store, max_epochs=1, threads=1)
    with pytest.raises(BadSetting, match="label_smoothing"):  # before the store is read
        api.train("no-such-corpus", store=store, label_smoothing=2.0)


def test_open_session_decides_as_the_commands_rollout_for_the_same_seed(trained, aoc, tmp_path):
    from aoc_cli.control import read_audit_step

    store, _done, _built = trained
    audit = tmp_path / "a.h5"
    code, _out, err = aoc("--store", str(store), "rollout", "g", "--env", "two-gates",
                          "--episodes", "1", "--seed", "3", "--audit", str(audit))
    assert code == 0, err
    recorded = read_audit_step(audit, 0, 0)
    session = api.open_session("g", store=store, env="two-gates", seed=3)
    decision = session.controller.decide(recorded["observation"], recorded["history"])
    np.testing.assert_array_equal(np.asarray(decision.action, np.float32).reshape(-1),
                                  np.asarray(recorded["action"], np.float32).reshape(-1))


def test_controller_takes_a_config_or_a_mapping_over_the_models_own_settings(trained):
    from aoc_cli.control import ControllerConfig

    store, done, _built = trained
    # the model carries the epsilon aoc train decided (continuous actions: on held-out
    # episodes); a mapping's None is "not given"
    own = done.metrics["controller"]["epsilon"]
    assert 0.1 <= own <= 0.5
    assert api.open_session("g", store=store).controller.config.epsilon == own
    mapped = api.open_session("g", store=store, controller={"epsilon": None, "k": 9,
                                                            "row_smoothing": 0.5})
    assert (mapped.controller.config.epsilon, mapped.controller.config.k,
            mapped.controller.config.row_smoothing) == (own, 9, 0.5)
    config = ControllerConfig(epsilon=0.7, candidates=12)
    assert api.open_session("g", store=store, controller=config).controller.config == config
    with pytest.raises(BadSetting, match="unknown controller setting epsilonn") as bad:
        api.open_session("g", store=store, controller={"epsilonn": 0.2})
    assert bad.value.param == "epsilonn"
    with pytest.raises(BadSetting, match="residual_cap must be > 0"):
        api.evaluate("g", "g", store=store, controller={"residual_cap": 0})
    with pytest.raises(BadSetting, match="epsilon does not apply to two-gates"):
        api.bench("two-gates", store=store, scale="tiny", controller={"epsilon": 0.3})


def test_rollout_explain_and_evaluate_return_what_the_commands_print(trained, tmp_path):
    store, _done, _built = trained
    audit = tmp_path / "b.h5"
    done = api.rollout("g", "two-gates", store=store, episodes=2, seed=5, audit=audit)
    assert [r.seed for r in done.results] == [5, 6] and audit.is_file()
    assert done.summary["episodes"] == 2
    replay = api.explain("g", store=store, audit=audit, episode=1, step=2)
    rec, = replay.records
    assert rec["recorded_action"] == pytest.approx(rec["action"], abs=1e-6)
    assert rec["support"] and abs(sum(s["weight"] for s in rec["support"]) - 1) < 1e-4
    again, = api.explain_recorded("g", audit, 1, 2, store=store).records
    assert again["action"] == rec["action"] and again["residual"] == rec["residual"]
    logged = api.explain("g", store=store, data="g", episode=1, step=3,
                         without={"policy": ["upper-gate"]})
    assert all("what_if" in r for r in logged.records)
    entry = api.explain_logged("g", "g", 1, 3, store=store, without={"policy": ["upper-gate"]})
    assert [r["action"] for r in entry.records] == [r["action"] for r in logged.records]
    queries = tmp_path / "q.jsonl"
    queries.write_text(json.dumps({"observation": rec["observation"]}) + "\n")
    asked, = api.explain_queries("g", queries, store=store, compare=[[0.5, 0.5]]).records
    assert asked["query"] == 1 and asked["action"] == [0.5, 0.5]
    summary = api.evaluate("g", "g", store=store, baselines=["knn"])
    assert summary["steps"] == Store(store).corpus("g").n_rows
    assert set(summary["baselines"]) == {"knn"}
    with pytest.raises(BadSetting, match="^episodes must be >= 1") as bad:
        api.rollout("g", "two-gates", store=store, episodes=0)
    assert bad.value.param == "episodes" and bad.value.value == 0
    with pytest.raises(AocError, match="give one of"):
        api.explain("g", store=store)


def test_bench_refuses_an_output_folder_inside_the_store_and_an_unknown_scale(tmp_path):
    with pytest.raises(AocError, match="inside the corpus store"):
        api.bench("two-gates", store=tmp_path, out=tmp_path / "x")
    with pytest.raises(BadSetting, match="'huge' is unknown") as bad:
        api.bench("two-gates", store=tmp_path / "s", scale="huge")
    assert bad.value.param == "scale"
