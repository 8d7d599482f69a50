"""aoc bench icu-cohort: the peers' true survival on a tiny cohort, the outputs, the errors."""

import json

import pytest

from aoc_cli.baselines.common import MissingExtra
from aoc_cli.envs import icu_cohort
from aoc_cli.errors import AocError, BadSetting
from aoc_cli.experiments import cohort
from aoc_cli.experiments.cohort import REFERENCES, run_cohort

#: Every method but AOC (its training is the slow part; tests/quality covers its cohort path).
PEERS = ["bc", "cql", "spibb", *REFERENCES]


def test_tiny_run_values_every_peer_paired_and_writes_the_outputs(tmp_path):
    pytest.importorskip("d3rlpy", reason="the bench extra (d3rlpy)")
    report = run_cohort(tmp_path / "out", tmp_path / "store", "tiny", methods=PEERS)
    rows = report["rows"]
    assert [r["method"] for r in rows] == PEERS
    by = {r["method"]: r for r in rows}
    assert all(r["status"] == "ok" and r["stays"] == 200 and r["noise"] == 0.3 for r in rows)
    rolled = [r for r in rows if r["kind"] == "monte-carlo"]
    assert {r["method"] for r in rolled} == {"bc", "cql", "clinicians-nearest",
                                             "modal-nearest", "optimal-nearest"}
    # paired: every rolled-out method on the same episodes
    assert {(r["rollout_seed"], r["episodes"]) for r in rolled} == {(10_000, 100)}
    for r in rows:
        assert 0.0 <= r["value"] <= 1.0 and r["low"] <= r["value"] <= r["high"]
    assert by["clinicians"]["value"] == icu_cohort.clinicians_value()
    assert by["clinicians"]["kind"] == by["spibb"]["kind"] == "exact"
    assert by["spibb"]["sees"] == "told the state"
    assert by["spibb"]["value"] >= by["clinicians"]["value"]
    assert by["optimal"]["value"] >= by["spibb"]["value"]
    saved = json.loads((tmp_path / "out" / "summary.json").read_text())
    assert saved["summary"] == report["summary"] and saved["episodes"] == 100
    md = (tmp_path / "out" / "summary.md").read_text()
    assert "| spibb | told the state | 200 | 0.3 | 1 |" in md
    assert (tmp_path / "out" / "results.csv").read_text().startswith("task,stays,noise,rows")


def test_every_method_is_set_against_aoc_on_the_same_episodes(tmp_path, monkeypatch):
    """AOC's row replaced by the optimal policy through the nearest centre: against that same
    policy rolled out on the same episodes the paired difference is exactly 0; against the
    others it is the difference of the values, with the interval of the per-episode
    differences; against an exact value, AOC's own interval less it."""
    optimal = icu_cohort.nearest_centre_policy(icu_cohort.optimal_state_policy())

    class Session:
        history_length, controller = 0, optimal

    monkeypatch.setattr(cohort, "train_aoc", lambda *_a, **_k: ({"val_r2": None}, Session))
    monkeypatch.setattr(cohort, "BatchPolicy", lambda controller: controller)
    methods = ["aoc", "optimal-nearest", "modal-nearest", "clinicians"]
    report = run_cohort(tmp_path / "out", tmp_path / "store", "tiny", methods=methods,
                        episodes=400)
    by = {r["method"]: r for r in report["rows"]}
    assert by["aoc"]["aoc_minus"] is None and by["aoc"]["ahead"] is None
    same = by["optimal-nearest"]
    assert by["aoc"]["value"] == same["value"]
    assert (same["aoc_minus"], same["aoc_minus_low"], same["aoc_minus_high"]) == (0, 0, 0)
    assert (same["aoc_minus_kind"], same["ahead"]) == ("paired", "not shown apart")
    modal = by["modal-nearest"]
    seed = cohort.rollout_seed(0)
    mine = icu_cohort.rollout_value(optimal, 400, noise=0.3, seed=seed)["survived"]
    theirs = icu_cohort.rollout_value(icu_cohort.nearest_centre_policy(
        icu_cohort.sepsis.tables("mean").modal()), 400, noise=0.3, seed=seed)["survived"]
    d = mine.astype(float) - theirs
    half = 1.96 * d.std(ddof=1) / len(d) ** 0.5
    assert modal["aoc_minus"] == pytest.approx(by["aoc"]["value"] - modal["value"], abs=1e-12)
    assert modal["aoc_minus_low"] == pytest.approx(d.mean() - half, rel=1e-12)
    # paired: narrower than two independent intervals would be
    assert modal["aoc_minus_high"] - modal["aoc_minus_low"] < (
        (by["aoc"]["high"] - by["aoc"]["low"]) ** 2 + (modal["high"] - modal["low"]) ** 2) ** 0.5
    assert modal["ahead"] == ("shown ahead" if modal["aoc_minus_low"] > 0 else
                              "shown behind" if modal["aoc_minus_high"] < 0 else
                              "not shown apart")
    clin = by["clinicians"]
    assert clin["aoc_minus_kind"] == "against exact"
    assert clin["aoc_minus_low"] == pytest.approx(by["aoc"]["low"] - clin["value"], abs=1e-12)
    summary = {r["method"]: r for r in report["summary"]}
    assert summary["modal-nearest"]["aoc_minus"] == modal["aoc_minus"]
    md = (tmp_path / "out" / "summary.md").read_text()
    assert "| +0.0000 | +0.000 - +0.000 | not shown apart (paired) |" in md


def test_without_d3rlpy_its_methods_are_skipped_with_a_note(tmp_path, monkeypatch):
    def missing(*_a, **_k):
        raise MissingExtra("the cql baseline needs the package 'd3rlpy': run "
                           "`pip install -e .[bench]`")

    monkeypatch.setattr(cohort, "train_agent", missing)
    report = run_cohort(tmp_path / "out", tmp_path / "store", "tiny",
                        methods=["cql", "clinicians"])
    cql = report["summary"][0]
    assert (cql["method"], cql["status"], cql["value"]) == ("cql", "skipped", None)
    assert "pip install" in cql["note"]
    assert "| cql | noisy features | 200 | 0.3 | 0 | skipped |" in \
        (tmp_path / "out" / "summary.md").read_text()


def test_bad_arguments_are_refused(tmp_path):
    with pytest.raises(AocError, match="unknown nope"):
        run_cohort(tmp_path / "o", tmp_path / "s", "tiny", methods=["nope"])
    with pytest.raises(BadSetting, match="noise"):
        run_cohort(tmp_path / "o", tmp_path / "s", "tiny", methods=["spibb"], noises=[-1.0])
    with pytest.raises(BadSetting, match="stays per cohort"):
        run_cohort(tmp_path / "o", tmp_path / "s", "tiny", methods=["spibb"], sizes=[0])
    with pytest.raises(BadSetting, match="episodes"):
        run_cohort(tmp_path / "o", tmp_path / "s", "tiny", methods=["spibb"], episodes=0)


def test_cli_noise_is_icu_cohorts_alone(aoc, tmp_path):
    code, _out, err = aoc("bench", "icu-sepsis", "--tiny", "--noise", "0.3",
                          "--out", str(tmp_path / "o"), "--bench-store", str(tmp_path / "s"))
    assert code == 2 and "--noise is icu-cohort's alone" in err
