"""`aoc bench` at the tiny scale: every experiment writes outputs that parse and agree with each
other; a small run shows a real effect; bad input is one line, exit 2."""

from __future__ import annotations

import json
from collections import defaultdict

import numpy as np
import pytest
from PIL import Image

from aoc_cli.experiments import EXPERIMENTS, run_experiment
from aoc_cli.experiments.results import METRICS, read_csv


@pytest.fixture(scope="module")
def bench_store(tmp_path_factory):
    """One bench store per test module and worker: experiments reuse each other's corpora."""
    return tmp_path_factory.mktemp("bench") / "store"


def _check_outputs(out, report):
    rows = read_csv(out / "results.csv")
    summary = json.loads((out / "summary.json").read_text())["summary"]
    markdown = (out / "summary.md").read_text()
    assert rows and summary
    assert len(rows) == len(report["rows"])
    # csv vs summary: every metric's summary mean is the mean of the seeds' csv values
    groups = defaultdict(list)
    for r in rows:
        groups[(r["task"], r["method"], r["setting"])].append(r)
    assert set(groups) == {(s["task"], s["method"], s["setting"]) for s in summary}
    for s in summary:
        members = [r for r in groups[(s["task"], s["method"], s["setting"])]
                   if r["status"] == "ok"]
        assert s["seeds"] == len(members)
        for m in METRICS:
            vals = [r[m] for r in members if r[m] is not None]
            if vals:
                assert s[m] == pytest.approx(float(np.mean(vals)), rel=1e-9, abs=1e-12)
            else:
                assert s[m] is None
        # and the markdown table shows that mean
        if s["status"] == "ok" and s.get("return_mean") is not None:
            assert f"{s['return_mean']:.4g}" in markdown
        assert f"| {s['method']} | {s['setting']} |" in markdown
    for name in report["plots"]:
        with Image.open(out / name) as im:
            assert im.format == "PNG" and im.size[0] > 100
    return rows, summary


def test_pendulum_het_tiny_covers_every_method_task_and_the_data(tmp_path, bench_store):
    out = tmp_path / "pendulum-het"
    report = run_experiment("pendulum-het", "tiny", out=out, store=bench_store)
    rows, summary = _check_outputs(out, report)
    methods = {r["method"] for r in rows}
    assert methods >= {"aoc", "aoc-dynamics", "aoc-critic", "aoc-reward", "aoc-gamma0.9",
                       "aoc-normal-rows",
                       "knn", "1nn", "knn-belief",
                       "1nn-belief", "bc", "td3bc", "cql", "mpc", "zero", "random", "data"}
    # aoc-dynamics runs its own model, trained with the auxiliary head; aoc the paper's
    from aoc_cli.belief import load_model
    from aoc_cli.store import Store
    corpus = Store(bench_store).corpus(next(n for n in (r["note"] for r in rows
                                                         if r["method"] == "data")).split()[-1])
    assert load_model(corpus, "dynamics").config.dynamics_weight == 1.0
    assert load_model(corpus, "default").config.dynamics_weight == 0.0
    # the reference code's beliefs: each row its own model, trained on what its name says
    assert load_model(corpus, "critic").config.belief == "critic"
    assert load_model(corpus, "reward").config.belief == "reward"
    # aoc-gamma0.9: the value belief on the return-to-go at gamma 0.9, whose index (the hull's
    # values v^c) holds that return-to-go, not the default model's gamma 0.99 one
    from aoc_cli.belief.targets import discounted_return_to_go
    from aoc_cli.index import load_index
    short = load_model(corpus, "value-gamma0.9")
    assert (short.config.belief, short.config.gamma) == ("value", 0.9)
    want = discounted_return_to_go(corpus.rewards, corpus.episode_starts, 0.9)
    np.testing.assert_allclose(load_index(corpus, "value-gamma0.9").values, want, rtol=1e-12)
    assert not np.allclose(load_index(corpus, "default").values, want)
    assert {r["task"] for r in rows} == {"pendulum-het", "pendulum-het-upright"}
    zero_upright = next(r for r in rows if r["method"] == "zero"
                        and r["task"] == "pendulum-het-upright")
    assert zero_upright["return_mean"] == pytest.approx(0.0, abs=1e-9)  # the trivial task
    paper_aoc = next(s for s in summary if s["method"] == "aoc")["paper"]
    assert paper_aoc == [-1.39, 1.39]
    assert {p.split("_")[0] for p in report["plots"]} == {"pendulum-het",
                                                          "pendulum-het-upright"}


@pytest.mark.parametrize("name", ["epsilon", "k", "ood"])
def test_pendulum_ablations_and_ood_tiny(tmp_path, bench_store, name):
    out = tmp_path / name
    report = run_experiment(name, "tiny", out=out, store=bench_store)
    rows, summary = _check_outputs(out, report)
    aoc = [s for s in summary if s["task"] == "pendulum-het" and s["method"] == "aoc"]
    settings = [s["setting"] for s in aoc]
    if name in ("epsilon", "k"):
        # the same settings with the dynamics-head model
        dyn = [s["setting"] for s in summary
               if s["task"] == "pendulum-het" and s["method"] == "aoc-dynamics"]
        assert dyn == settings
    if name == "epsilon":
        assert settings == ["epsilon=0.3", "epsilon=0.5", "epsilon=0.9", "epsilon=1"]
        assert aoc[1]["paper"] == [-1.25, 0.4]
    elif name == "k":
        assert settings == ["k=1", "k=10", "k=42", "k=100"]
        assert aoc[2]["paper"] == [-1.25, 0.4]              # 2 (d_b + 1) is the paper's 20
    else:
        settings = [s["setting"] for s in summary if s["task"] == "pendulum-het"]
        assert settings == ["noise=0, band=running", "noise=0, band=reference",
                            "noise=0.5, band=running", "noise=0.5, band=reference"]
        for r in rows:
            assert r["ood_flagged"] in (0.0, 1.0) and r["ood_false_flags"] >= 0
        # the two bands score the same episodes: same returns and residuals
        by = {(r["task"], r["setting"]): r for r in rows}
        for task in ("pendulum-het", "maze"):
            for noise in ("0", "0.5"):
                run, ref = (by[(task, f"noise={noise}, band={b}")] for b in ("running", "reference"))
                assert ref["return_mean"] == run["return_mean"]
                assert ref["mean_residual"] == run["mean_residual"]
        assert {"ood_pendulum-het_mean.png", "ood_maze_mean.png"} <= set(report["plots"])
        assert {r["task"] for r in rows} == {"pendulum-het", "maze"}


def test_maze_adapt_tiny_counts_gates_and_draws_each_rate(tmp_path, bench_store):
    out = tmp_path / "maze"
    report = run_experiment("maze-adapt", "tiny", out=out, store=bench_store)
    rows, summary = _check_outputs(out, report)
    for r in rows:
        assert 0 <= r["upper_gate"] + r["lower_gate"] <= 100
    assert [s["setting"] for s in summary if s["method"] == "aoc"] == \
        ["rate=2", "rate=1", "rate=0.5"]
    assert {"maze_aoc_x2.png", "maze_aoc_x0.5.png", "maze_adapt.png"} <= set(report["plots"])
    built = {b["name"].rsplit("/", 1)[-1] for b in report["built"] if b["step"] == "index"}
    assert {"pi1x2", "pi1x0.5"} <= built <= {"pi1x2", "default", "pi1x0.5"}  # derived indexes
    trained = [b["name"] for b in report["built"] if b["step"] == "train"]
    assert all(t.endswith("/default") for t in trained) and len(trained) <= 1  # one model


def test_two_gates_and_lunar_tiny(tmp_path, bench_store):
    for name in ("two-gates", "lunar"):
        out = tmp_path / name
        report = run_experiment(name, "tiny", out=out, store=bench_store)
        rows, _summary = _check_outputs(out, report)
        methods = {r["method"] for r in rows}
        assert len(methods) == (1 if name == "two-gates" else 7)
        if name == "lunar":  # the reference code's beliefs beside the paper's AOC
            assert {"aoc", "aoc-critic", "aoc-reward", "data"} <= methods


def test_sizes_replace_the_data_sizes_of_a_sweep(tmp_path, bench_store):
    out = tmp_path / "lunar"
    report = run_experiment("lunar", "tiny", out=out, store=bench_store, sizes=[1_500, 2_500],
                            methods=["zero"])
    rows, _summary = _check_outputs(out, report)
    assert sorted({r["setting"] for r in rows}) == ["rows=1500", "rows=2500"]
    corpora = {b["name"] for b in report["built"] if b["step"] == "collect"}
    assert corpora == {"lunar-1500r-s0", "lunar-2500r-s0"}
    assert json.loads((out / "summary.json").read_text())["sizes"] == [1_500, 2_500]


def test_a_second_run_reuses_the_stored_artefacts(tmp_path, bench_store):
    run_experiment("two-gates", "tiny", out=tmp_path / "a", store=bench_store)
    again = run_experiment("two-gates", "tiny", out=tmp_path / "b", store=bench_store)
    assert again["built"] == []


def test_residual_cap_reaches_every_aoc_session_and_is_recorded(tmp_path, bench_store,
                                                                  monkeypatch):
    from aoc_cli.experiments import maze
    from aoc_cli.errors import BadSetting

    with pytest.raises(BadSetting, match="residual_cap must be > 0") as err:
        run_experiment("two-gates", "tiny", out=tmp_path / "bad", store=bench_store,
                       controller={"residual_cap": 0.0})
    assert (err.value.param, err.value.value) == ("residual_cap", 0.0)
    configs = []
    real = maze.session

    def spy(*args, **kw):
        s = real(*args, **kw)
        configs.append(s.controller.config)
        return s

    monkeypatch.setattr(maze, "session", spy)
    out = tmp_path / "capped"
    run_experiment("two-gates", "tiny", out=out, store=bench_store,
                   controller={"residual_cap": 2.5})
    assert [c.epsilon for c in configs] == [0.1, 0.7]  # epsilon still varies
    assert all(c.residual_cap == 2.5 for c in configs)
    meta = json.loads((out / "summary.json").read_text())
    assert meta["aoc_config"] == {"residual_cap": 2.5}
    assert "residual cap 2.5" in (out / "summary.md").read_text()


def test_pi1_copies_fill_the_nearest_entries_of_the_start_moves(bench_store):
    """maze-adapt's mechanism, measured: x2 copies of pi1 crowd the k nearest entries of both
    first moves (fewer distinct rows), while v_hat stays a weighted mean of row values."""
    from aoc_cli.experiments.common import belief_config, session
    from aoc_cli.experiments.maze import MAZE_EPSILON, SCALES, start_probe
    from aoc_cli.experiments.prepare import Artefacts
    from aoc_cli.envs import make_env

    art = Artefacts(bench_store)
    corpus = art.corpus("maze", episodes=SCALES["tiny"]["episodes_data"], seed=0)
    art.model(corpus, "default", belief_config(SCALES["tiny"], "value", 0))
    art.index(corpus, "default")
    art.index(corpus, "default", "pi1x2", resample={"policy=pi1": 2.0})
    env = make_env("maze")
    x1 = start_probe(session(corpus, env, epsilon=MAZE_EPSILON))
    x2 = start_probe(session(corpus, env, index_id="pi1x2", epsilon=MAZE_EPSILON))
    for move in ("pi1", "pi2"):
        assert x2[f"pi1_nearest_{move}"] > x1[f"pi1_nearest_{move}"]
        assert x2[f"distinct_nearest_{move}"] < x1[f"distinct_nearest_{move}"]
        assert 0.0 <= x2[f"pi1_support_{move}"] <= 1.0 + 1e-9
    values = session(corpus, env, epsilon=MAZE_EPSILON).index.values
    assert values.min() - 1e-9 <= x1["value_pi1"] <= values.max() + 1e-9


def test_the_gate_of_a_path_is_where_it_crosses_x_8():
    from aoc_cli.experiments.maze import gate_of

    assert gate_of(np.array([[0, 0], [7.5, 15], [8.5, 15.2], [16, 0]])) == "upper"
    assert gate_of(np.array([[0, 0], [7.6, 7.9], [8.4, 8.1]])) == "lower"
    assert gate_of(np.array([[0, 0], [7.9, 3.0]])) is None
    # a path that crosses back: the first crossing counts
    assert gate_of(np.array([[7, 8], [9, 8], [7.5, 15], [8.5, 15]])) == "lower"


def test_aoc_is_more_conservative_with_a_small_epsilon_on_two_gates(tmp_path):
    """A real effect (the paper's two-gates table): epsilon 0.1 keeps AOC on the data and
    reaches the goal; epsilon 0.7 lets it extrapolate into the wall."""
    from aoc_cli.experiments import maze
    from aoc_cli.experiments.execute import execute
    from aoc_cli.experiments.common import Context
    from aoc_cli.experiments.methods import Runner
    from aoc_cli.experiments.prepare import Artefacts

    scale = {"episodes_data": 200, "episodes": 6, "epochs": 12, "patience": 4,
             "epsilons": (0.1, 0.7)}
    ctx = Context("two-gates", "small", tmp_path, Artefacts(tmp_path / "store"), Runner(),
                  [0])
    rows = execute(maze.TWO_GATES, ctx, scale)
    by = {r["setting"]: r for r in rows}
    assert by["epsilon=0.1"]["success_rate"] >= 0.8
    assert by["epsilon=0.1"]["return_mean"] > by["epsilon=0.7"]["return_mean"] + 3.0


def test_bench_cli_prints_the_summary_and_rejects_bad_input(aoc, tmp_path):
    out, store = tmp_path / "tg", tmp_path / "store"
    code, stdout, stderr = aoc("bench", "two-gates", "--tiny", "--out", str(out),
                               "--bench-store", str(store), "--format", "json")
    assert code == 0, stderr
    printed = json.loads(stdout)
    summary = json.loads((out / "summary.json").read_text())["summary"]
    assert [(p["setting"], p["return_mean"]) for p in printed] == \
        [(s["setting"], s["return_mean"]) for s in summary]
    assert "expected time" in stderr
    for args, needle in [(["bench", "nope"], "unknown experiment"),
                         (["bench", "k", "--quick", "--tiny"], "not both"),
                         (["bench", "k", "--tiny", "--seeds", "0"], "--seeds"),
                         (["bench", "lunar", "--tiny", "--methods", "aoc,foo"], "foo"),
                         (["bench", "epsilon", "--tiny", "--epsilon", "0.2"], "does not apply"),
                         (["bench", "ood", "--tiny", "--epsilon", "1.5"], "(0, 1]"),
                         (["bench", "maze-adapt", "--tiny", "--sizes", "500"], "--sizes"),
                         (["bench", "lunar", "--tiny", "--sizes", "1e5x"], "row counts"),
                         (["bench", "lunar", "--tiny", "--sizes", "10"], ">= 100")]:
        code, _o, err = aoc(*args, "--bench-store", str(store))
        assert code == 2 and needle in err and len(err.strip().splitlines()) == 1
    assert set(EXPERIMENTS) == {"pendulum-het", "epsilon", "k", "maze-adapt", "two-gates",
                                "lunar", "ood"}


def test_a_stored_corpus_of_an_earlier_behaviour_mix_is_collected_again(tmp_path):
    from aoc_cli.experiments.prepare import Artefacts, corpus_name
    from aoc_cli.envs import TASKS, collect
    from aoc_cli.store import Store

    store = Store(tmp_path)
    art = Artefacts(tmp_path)
    first = art.corpus("pendulum-het", rows=400, seed=0)
    assert art.corpus("pendulum-het", rows=400, seed=0).hash == first.hash   # reused
    # the same name, but policies of another mix (as before a change of noise levels)
    data, _ = collect("pendulum-het", steps=400, seed=0)
    codes, labels = data.tags["policy"]
    data.tags["policy"] = (codes, [f"old-{x}" for x in labels])
    store.write(corpus_name("pendulum-het", 400, None, 0), data, overwrite=True)
    again = art.corpus("pendulum-het", rows=400, seed=0)
    assert list(again.tag("policy")[1]) == list(TASKS["pendulum-het"].policies)
    assert again.hash == first.hash


def test_bench_replay_data_is_its_own_corpus(tmp_path):
    from aoc_cli.experiments.prepare import Artefacts
    from aoc_cli.experiments.runner import check
    from aoc_cli.errors import AocError

    art = Artefacts(tmp_path / "store", behaviour="replay")
    corpus = art.corpus("pendulum-het", rows=2_000, seed=0)
    assert corpus.name == "pendulum-het-2000r-s0-replay"
    assert corpus.manifest["sources"][-1]["behaviour"] == "replay"
    assert corpus.tag("policy")[1][0] == "random"
    assert art.corpus("pendulum-het", rows=2_000, seed=0).hash == corpus.hash   # reused
    mix = Artefacts(tmp_path / "store").corpus("pendulum-het", rows=2_000, seed=0)
    assert mix.name == "pendulum-het-2000r-s0" and mix.hash != corpus.hash
    with pytest.raises(AocError, match="applies to pendulum-het and lunar"):
        check("maze-adapt", "tiny", None, None, behaviour="replay")
