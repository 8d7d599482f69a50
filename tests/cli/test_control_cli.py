"""`aoc index`, `aoc rollout` and `aoc explain` from the command line."""

import csv
import io
import json
import re

import numpy as np
import pytest

from tests.control.corpora import maze_store


@pytest.fixture(scope="module")
def maze_root(tmp_path_factory):
    root = tmp_path_factory.mktemp("cli-maze")
    maze_store(root)
    return root


@pytest.fixture
def run(aoc_inproc, maze_root):
    return lambda *args: aoc_inproc("--store", str(maze_root), *args)


def one_line_error(code, out, err, pattern):
    assert code == 2 and out == "", (code, out, err)
    lines = err.strip().splitlines()
    assert len(lines) == 1 and re.search(pattern, lines[0]), err


def test_rollout_json_has_episodes_and_summary_that_agree(run):
    code, out, err = run("rollout", "maze", "--env", "maze", "-n", "3", "--seed", "7", "-f", "json")
    assert code == 0, err
    doc = json.loads(out)
    eps = doc["episodes"]
    assert len(eps) == 3 and {"return", "length", "success", "ood_steps", "mean_residual"} <= set(eps[0])
    s = doc["summary"]
    assert s["return_mean"] == pytest.approx(np.mean([e["return"] for e in eps]))
    assert s["success_rate"] == pytest.approx(np.mean([e["success"] for e in eps]))
    assert s["seconds_per_step"] > 0


def test_rollout_csv_and_jsonl_carry_the_same_numbers_as_json(run):
    args = ("rollout", "maze", "--env", "maze", "-n", "2", "--seed", "11")
    doc = json.loads(run(*args, "-f", "json")[1])
    lines = [json.loads(x) for x in run(*args, "-f", "jsonl")[1].splitlines()]
    rows = list(csv.DictReader(io.StringIO(run(*args, "-f", "csv")[1])))
    code, table, _ = run(*args, "-f", "table")
    for e, l, r in zip(doc["episodes"], lines, rows):
        assert l["return"] == pytest.approx(e["return"])
        assert float(r["return"]) == pytest.approx(e["return"], rel=1e-5)
        assert f"{e['return']:.6g}" in table


def test_audit_log_replays_the_recorded_decision_exactly(run, tmp_path):
    audit = tmp_path / "audit.h5"
    code, _, err = run("rollout", "maze", "--env", "maze", "-n", "1", "--seed", "3",
                       "--audit", str(audit), "-f", "json")
    assert code == 0 and audit.is_file(), err
    code, out, err = run("explain", "maze", "--audit", str(audit), "--episode", "0",
                         "--step", "4", "-f", "json")
    assert code == 0, err
    rec = json.loads(out)
    assert rec["action"] == rec["recorded_action"]
    assert abs(sum(s["weight"] for s in rec["support"]) - 1) < 1e-9
    assert rec["candidates"]["passed"] <= rec["candidates"]["count"]
    # the same numbers in the table
    code, table, _ = run("explain", "maze", "--audit", str(audit), "--episode", "0",
                         "--step", "4", "-f", "table")
    assert f"{rec['residual']:.6g}" in table and f"{rec['support'][0]['weight']:.6g}" in table
    code, out, err = run("explain", "maze", "--audit", str(audit), "--episode", "0", "--step", "999")
    one_line_error(code, out, err, "no step 999")
    code, out, err = run("explain", "maze", "--audit", str(audit), "--episode", "5", "--step", "0")
    one_line_error(code, out, err, "no episode 5")


def test_residual_cap_reaches_the_controller_and_the_audit_log(run, tmp_path):
    audit = tmp_path / "capped.h5"
    code, _, err = run("rollout", "maze", "--env", "maze", "-n", "1", "--seed", "3",
                       "--epsilon", "0.5", "--residual-cap", "1e-9", "--audit", str(audit),
                       "-f", "json")
    assert code == 0, err
    code, out, err = run("explain", "maze", "--audit", str(audit), "--episode", "0",
                         "--step", "2", "-f", "json")
    assert code == 0, err
    rec = json.loads(out)
    # a cap far below every residual: only the fallback, the smallest-residual candidate, passes
    assert rec["candidates"]["passed"] == 1
    assert rec["action"] == rec["recorded_action"]


def test_explain_jsonl_queries_and_compare(run, tmp_path):
    queries = tmp_path / "q.jsonl"
    queries.write_text(
        json.dumps({"observation": [2.0, 2.0], "history": [[1.3, 1.3, 0.7, 0.7, -0.1]]}) + "\n"
        + json.dumps({"observation": [2.0, 2.0], "action": [0.7, 0.7]}) + "\n")
    code, out, err = run("explain", "maze", "--input", str(queries), "-f", "jsonl")
    assert code == 0, err
    recs = [json.loads(x) for x in out.splitlines()]
    assert len(recs) == 2 and all(isinstance(r["residual"], float) for r in recs)
    assert recs[1]["action"] == [0.7, 0.7]
    for r in recs:
        rows = [s["row"] for s in r["support"]]
        assert len(rows) <= 21 and all(isinstance(x, int) for x in rows)
    code, out, err = run("explain", "maze", "--input", str(queries), "--compare", "1,0",
                         "--compare", "0.7,0.7", "-f", "csv")
    assert code == 0, err
    rows = list(csv.DictReader(io.StringIO(out)))
    assert {r["action"] for r in rows} == {"[1.0,0.0]", "[0.7,0.7]"}
    assert {"support_row", "support_weight", "tag_policy"} <= set(rows[0])


def test_explain_a_logged_step_of_the_corpus_and_of_held_out_episodes(run, maze_root):
    from aoc_cli.envs import collect
    from aoc_cli.store import Store

    store = Store(maze_root)
    corpus = store.corpus("maze")
    episode, step = 300, 4
    row = int(corpus.episode_starts[episode]) + step
    code, out, err = run("explain", "maze", "--data", "maze", "--episode", str(episode),
                         "--step", str(step), "-f", "jsonl")
    assert code == 0, err
    decision, logged = [json.loads(x) for x in out.splitlines()]
    assert (decision["role"], logged["role"]) == ("decision", "logged action")
    assert decision["row"] == logged["row"] == row and decision["episode_left_out"]
    # the model (trained by the library's train_model) carries no controller settings: the
    # paper's epsilon 0.5, as in rollout; a flag overrides it
    assert decision["candidates"]["passed"] == 50
    code, out, err = run("explain", "maze", "--data", "maze", "--episode", str(episode),
                         "--step", str(step), "--epsilon", "0.1", "-f", "jsonl")
    assert json.loads(out.splitlines()[0])["candidates"]["passed"] == 10
    np.testing.assert_allclose(decision["logged_action"], corpus.actions[row])
    np.testing.assert_allclose(logged["action"], corpus.actions[row])
    for rec in (decision, logged):
        # the episode's own rows are left out, and v_hat is the weighted value of the rows
        assert all(s["episode"] != episode for s in rec["support"])
        assert rec["value"] == pytest.approx(sum(s["weight"] * s["value"]
                                                 for s in rec["support"]), abs=1e-9)
    # the table shows both blocks
    code, table, err = run("explain", "maze", "--data", "maze", "--episode", str(episode),
                           "--step", str(step), "-f", "table")
    assert "decision (maze episode 300, step 4)" in table
    assert "logged action (maze episode 300, step 4)" in table
    # held-out episodes of the same task: explained against the whole corpus
    held, _ = collect("maze", episodes=8, seed=77)
    store.write("maze-held", held, overwrite=True)
    code, out, err = run("explain", "maze", "--data", "maze-held", "--episode", "5",
                         "--step", "2", "-f", "json")
    assert code == 0, err
    recs = json.loads(out)["decisions"]
    assert [r["data"] for r in recs] == ["maze-held", "maze-held"]
    assert not recs[0]["episode_left_out"]
    np.testing.assert_allclose(recs[1]["action"], held.actions[held.episode_starts[5] + 2])


def test_explain_refuses_held_out_data_of_other_spaces(run, maze_root):
    from aoc_cli.envs import collect
    from aoc_cli.store import Store

    data, _ = collect("pendulum-het", steps=400, seed=0)
    Store(maze_root).write("pend-small", data, overwrite=True)
    one_line_error(*run("explain", "maze", "--data", "pend-small"),
                   r"corpus 'pend-small' does not match 'maze'")


def test_rollout_select_uses_only_that_policy(run, tmp_path, maze_root):
    from aoc_cli.control import read_audit_step
    from aoc_cli.store import Store

    audit = tmp_path / "a.h5"
    code, _, err = run("rollout", "maze", "--env", "maze", "-n", "1", "--select", "policy=pi2",
                       "--audit", str(audit), "-f", "json")
    assert code == 0, err
    corpus = Store(maze_root).corpus("maze")
    codes, labels = corpus.tag("policy")
    import h5py

    with h5py.File(audit) as f:
        rows = f["episode_0/support_rows"][()]
    assert set(codes[rows[rows >= 0]]) == {labels.index("pi2")}
    # explain --audit replays each decision over the rows it was made from, not all of them
    for step in range(min(len(rows), 6)):
        code, out, err = run("explain", "maze", "--audit", str(audit), "--episode", "0",
                             "--step", str(step), "-f", "json")
        assert code == 0, err
        rec = json.loads(out)
        replayed = sorted(s["row"] for s in rec["support"])
        assert replayed == sorted(r for r in rows[step] if r >= 0)
        assert rec["action"] == rec["recorded_action"]
        assert {int(codes[r]) for r in replayed} == {labels.index("pi2")}


def test_an_older_audit_log_replays_its_listed_rows_or_says_it_cannot(run, tmp_path):
    """Logs written before the mask was kept: the meta's list of rows (under 10,000) is the
    selection; a log of more rows kept only a marker, and explain says so in one line."""
    import shutil

    import h5py

    audit = tmp_path / "a.h5"
    code, _, err = run("rollout", "maze", "--env", "maze", "-n", "1", "--select", "policy=pi2",
                       "--audit", str(audit), "-f", "json")
    assert code == 0, err
    args = ("explain", "maze", "--episode", "0", "--step", "3", "-f", "json")
    new = json.loads(run(*args[:2], "--audit", str(audit), *args[2:])[1])
    listed, lost = tmp_path / "listed.h5", tmp_path / "lost.h5"
    for path, marker in ((listed, None), (lost, "mask")):
        shutil.copy(audit, path)
        with h5py.File(path, "a") as f:
            del f["selection"]
            meta = json.loads(f.attrs["meta"])
            assert isinstance(meta["selection"], list) and meta["selection"]
            if marker:
                meta["selection"] = marker
            f.attrs["meta"] = json.dumps(meta)
    code, out, err = run(*args[:2], "--audit", str(listed), *args[2:])
    assert code == 0, err
    assert json.loads(out)["support"] == new["support"]
    one_line_error(*run(*args[:2], "--audit", str(lost), *args[2:]),
                   r"recorded from a selection of the corpus rows that it does not hold")


@pytest.mark.parametrize("args, pattern", [
    (["rollout", "maze", "--env", "NoSuchEnv-v9"], "unknown environment|NoSuchEnv"),
    (["rollout", "maze", "--env", "pendulum-het"], "observations have 3 dimensions"),
    (["rollout", "maze", "--env", "maze", "--epsilon", "0"], "--epsilon must be in"),
    (["rollout", "maze", "--env", "maze", "--epsilon", "1.5"], "--epsilon must be in"),
    (["rollout", "maze", "--env", "maze", "--k", "0"], "--k must be >= 1"),
    (["rollout", "maze", "--env", "maze", "--residual-cap", "0"], "--residual-cap must be > 0"),
    (["bench", "two-gates", "--tiny", "--residual-cap", "-1"], "--residual-cap must be > 0"),
    (["rollout", "nope", "--env", "maze"], "no corpus 'nope'"),
    (["rollout", "maze", "--env", "maze", "--select", "policy=pi9"], "has no value 'pi9'"),
    (["index", "maze", "--model", "nope"], "no model 'nope'"),
    (["index", "maze", "--resample", "policy=pi1"], "TAG=VALUE:RATE"),
    (["explain", "maze"], "give one of --input"),
    (["explain", "maze", "--data", "maze", "--audit", "a.h5"], "give one of --input"),
    (["explain", "maze", "--data", "maze", "--episode", "480"], "episodes 0..479, not 480"),
    (["explain", "maze", "--data", "maze", "--episode", "0", "--step", "500"],
     r"episode 0 of corpus 'maze' has steps 0\.\.\d+, not 500"),
    (["explain", "maze", "--data", "nope"], "no corpus 'nope'"),
    (["rollout", "maze", "--env", "maze", "--ood-reference", "/no/such.h5"],
     r"audit log /no/such.h5 does not exist: record one with `aoc rollout"),
    (["explain", "maze", "--audit", "/no/such.h5", "--episode", "0", "--step", "0"],
     r"does not exist"),
])
def test_bad_input_is_one_line_and_exit_2(run, args, pattern):
    one_line_error(*run(*args), pattern)


@pytest.mark.parametrize("line, pattern", [
    ("{not json", "line 1 of the input is not valid JSON"),
    (json.dumps({"observation": [1.0, 2.0, 3.0]}), "line 1: observation has 3 numbers"),
    (json.dumps({"observation": [1.0, 2.0], "history": [[1, 2, 3]]}), "history step 0 has 3"),
    (json.dumps({"observation": [1.0, 2.0], "action": [1, 2, 3]}), "has 2 numbers, got 3"),
])
def test_malformed_queries_name_the_line(run, tmp_path, line, pattern):
    q = tmp_path / "bad.jsonl"
    q.write_text(line + "\n")
    one_line_error(*run("explain", "maze", "--input", str(q)), pattern)


def test_index_refuses_a_model_whose_corpus_changed(aoc_inproc, tmp_path):
    from aoc_cli.envs import collect
    from aoc_cli.store import Store

    root = tmp_path / "s"
    maze_store(root)
    data, _ = collect("maze", episodes=40, seed=1)
    Store(root).write("maze", data, append=True)
    code, out, err = aoc_inproc("--store", str(root), "rollout", "maze", "--env", "maze")
    one_line_error(code, out, err, "trained on a different version.*--overwrite")


def test_derived_index_resamples_a_policy_without_retraining(run, maze_root):
    code, out, err = run("index", "maze", "--index-id", "pi1x3", "--resample", "policy=pi1:3",
                         "-f", "json")
    assert code == 0, err
    from aoc_cli.store import Store

    corpus = Store(maze_root).corpus("maze")
    codes, labels = corpus.tag("policy")
    n_pi1 = int((codes == labels.index("pi1")).sum())
    assert json.loads(out)["rows"] == corpus.n_rows + 2 * n_pi1
    # --episode-rate is the documented name of --resample: 0.5 keeps half of pi1's episodes
    code, out, err = run("index", "maze", "--index-id", "pi1half", "--episode-rate",
                         "policy=pi1:0.5", "-f", "json")
    assert code == 0, err
    meta = json.loads((corpus.models_dir / "default" / "index" / "pi1half" / "index.json")
                      .read_text())
    assert meta["episode_rates"] == {"policy=pi1": 0.5}
    episodes = np.unique(corpus.episode_of(np.flatnonzero(codes == labels.index("pi1"))))
    kept = json.loads(out)["rows"] - (corpus.n_rows - n_pi1)
    assert len(episodes) > 1 and 0 < kept < n_pi1
    code, out, err = run("rollout", "maze", "--env", "maze", "--index", "pi1x3", "-n", "1", "-f", "json")
    assert code == 0, err


@pytest.mark.parametrize("kind", ["hnsw", "ivf"])
def test_approximate_index_kinds_build_and_answer_like_the_exact_one(run, tmp_path, kind):
    code, out, err = run("index", "maze", "--kind", kind, "--index-id", kind, "-f", "json")
    assert code == 0, err
    assert json.loads(out)["kind"] == kind
    q = tmp_path / "q.jsonl"
    q.write_text(json.dumps({"observation": [3.0, 2.5], "action": [0.6, 0.7]}) + "\n")
    exact = json.loads(run("explain", "maze", "-i", str(q), "-f", "json")[1])
    approx = json.loads(run("explain", "maze", "-i", str(q), "--index", kind, "-f", "json")[1])
    assert approx["residual"] == pytest.approx(exact["residual"], rel=1e-6, abs=1e-9)
    assert approx["value"] == pytest.approx(exact["value"], rel=1e-6, abs=1e-9)


def test_index_of_a_corpus_without_a_model_says_to_train(aoc_inproc, tmp_path):
    from aoc_cli.envs import collect
    from aoc_cli.store import Store

    data, _ = collect("maze", episodes=8, seed=0)
    Store(tmp_path).write("bare", data)
    code, out, err = aoc_inproc("--store", str(tmp_path), "index", "bare")
    one_line_error(code, out, err, r"no trained model: run `aoc train bare`")


def test_zero_and_random_run_on_a_corpus_without_a_model(aoc_inproc, tmp_path):
    """The trivial baselines act without the data: no model or index is needed; the AOC
    controller on the same corpus still says what to train."""
    from aoc_cli.envs import collect, make_env
    from aoc_cli.store import Store

    data, _ = collect("pendulum-het", steps=400, seed=0)
    Store(tmp_path).write("bare", data)
    args = ("--store", str(tmp_path), "rollout", "bare", "--env", "pendulum-het", "-n", "2",
            "--seed", "5")
    code, out, err = aoc_inproc(*args, "--policy", "zero", "-f", "json")
    assert code == 0, err
    doc = json.loads(out)
    # the do-nothing return, replayed by hand on the same seeds
    expected = []
    for seed in (5, 6):
        env = make_env("pendulum-het")
        env.reset(seed=seed)
        total, done = 0.0, False
        while not done:
            _o, r, term, trunc, _i = env.step(np.zeros(1, np.float32))
            total, done = total + r, term or trunc
        expected.append(total)
    assert [e["return"] for e in doc["episodes"]] == pytest.approx(expected)
    assert all(e["mean_residual"] is None for e in doc["episodes"])
    code, out, err = aoc_inproc(*args, "--policy", "random", "-f", "json")
    assert code == 0, err
    returns = [e["return"] for e in json.loads(out)["episodes"]]
    assert returns != pytest.approx(expected)
    one_line_error(*aoc_inproc(*args), r"no trained model: run `aoc train bare`")


def test_ood_reference_band_from_a_clean_audit_log(run, tmp_path, maze_root):
    """--ood-reference: each step is flagged against the per-step band of a clean rollout's
    residuals (rebuilt here from the two audit logs), not the running band."""
    import h5py

    from aoc_cli.control.monitor import OODMonitor, flags_against, reference_band
    from aoc_cli.index import load_index
    from aoc_cli.store import open_corpus

    clean, test = tmp_path / "clean.h5", tmp_path / "test.h5"
    code, _out, err = run("rollout", "maze", "--env", "maze", "-n", "3", "--seed", "300",
                          "--audit", str(clean), "-f", "json")
    assert code == 0, err
    code, out, err = run("rollout", "maze", "--env", "maze", "-n", "2", "--seed", "7",
                         "--noise-after", "12", "--noise-std", "0.5",
                         "--ood-reference", str(clean), "--audit", str(test), "-f", "json")
    assert code == 0, err
    reported = [e["ood_steps"] for e in json.loads(out)["episodes"]]
    typical = load_index(open_corpus("maze", maze_root)).meta["typical_residual"]
    with h5py.File(clean) as f:
        runs = [f[k]["residuals"][()] for k in sorted(f) if k.startswith("episode_")]
    band = reference_band(runs, floor=0.1 * typical["p50"], minimum=typical["p99"])
    differs = False
    with h5py.File(test) as f:
        for e, count in enumerate(reported):
            g = f[f"episode_{e}"]
            expected = flags_against(g["residuals"][()], band)
            np.testing.assert_array_equal(g["ood"][()], expected)
            assert count == int(expected.sum())
            running = OODMonitor(floor=0.1 * typical["p50"], minimum=typical["p99"])
            differs |= [running.update(r) for r in g["residuals"][()]] != expected.tolist()
    assert differs  # the running band would have flagged other steps
    # a policy without residuals, and a log of another model, are refused in one line
    one_line_error(*run("rollout", "maze", "--env", "maze", "-n", "1", "--policy", "zero",
                        "--ood-reference", str(clean)), r"--ood-reference needs the AOC")
    with h5py.File(clean, "r+") as f:
        meta = json.loads(f.attrs["meta"])
        meta["model_hash"] = "0" * 32
        f.attrs["meta"] = json.dumps(meta)
    one_line_error(*run("rollout", "maze", "--env", "maze", "-n", "1",
                        "--ood-reference", str(clean)), r"another version of the corpus or model")


def test_rollout_help_names_every_baseline(run):
    from aoc_cli.baselines import BASELINES

    code, out, err = run("rollout", "--help")
    assert code == 0, err
    text = " ".join(out.replace("│", " ").split())
    assert all(f" {name}," in text or f" {name} " in text for name in BASELINES), text
