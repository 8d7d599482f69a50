"""What ``aoc evaluate`` prints as tables: the OPE's rows (each policy's estimates with their
intervals, the logged behaviour's mean return and FQE's value of it) and the value target."""

from aoc_cli.cli.evaluate_view import _ope_rows, write_evaluation


def _summary(fqe=0.7754):
    est = lambda v: {"estimate": v, "low": v - 0.01, "high": v + 0.01}
    return {"mode": "value", "corpus": "icu", "model": "default", "data": "held",
            "own_episode_left_out": False, "steps": 10, "episodes": 2,
            "extrapolating_share": 0.0, "heterogeneity_share": 0.0, "support_max": 3,
            "search": "exact", "seconds": 1.0, "steps_per_second": 10.0,
            "residual": {"p50": 0.0, "p90": 0.0, "p99": 0.0, "typical": 0.01},
            "value_r2": 0.4, "value_target": "the logged behaviour's Q(o, a) by d3rlpy",
            "policy_value": {"fqe": est(0.81)}, "ess": 1.5,
            "behaviour_value": {**est(0.7786), **({} if fqe is None else {"fqe": fqe})},
            "ope": {"propensity": "column 'propensity' of 'held'"},
            "baselines": {"bc": {"value_r2": 0.3, "policy_value": {"fqe": est(0.79)},
                                 "ess": 1.6}}}


def test_the_behaviour_row_holds_its_mean_return_and_fqes_value_of_it():
    rows = _ope_rows(_summary())
    assert [r["policy"] for r in rows] == ["aoc", "bc", "behaviour"]
    assert rows[0]["fqe"] == "0.8100 [0.8000, 0.8200]"
    assert rows[-1] == {"policy": "behaviour", "mean_return": "0.7786 [0.7686, 0.7886]",
                        "fqe": "0.7754"}
    assert "fqe" not in _ope_rows(_summary(fqe=None))[-1]


def test_the_table_says_what_value_r2_was_measured_against(capsys):
    write_evaluation(_summary(), "table")
    out = capsys.readouterr().out
    assert "value target" in out and "the logged behaviour's Q(o, a) by d3rlpy" in out
    assert "0.7754" in out


def test_a_withheld_estimate_reads_not_estimable_and_the_verdict_has_its_line(capsys):
    summary = _summary()
    summary["policy_value"] = {"pdwis": {"estimate": None, "low": None, "high": None,
                                         "reason": "ESS 4.6 of 3,000 (the rule asks 500)"},
                               "fqe": {"estimate": 0.81, "low": 0.8, "high": 0.82}}
    summary["verdict"] = ("better than the logged behaviour by 0.019 [-0.004, 0.041] (FQE): "
                          "not shown by this log")
    summary["support"] = {"reached": 0.93}
    rows = _ope_rows(summary)
    assert rows[0]["pdwis"] == "not estimable: ESS 4.6 of 3,000"
    assert rows[0]["reached"] == 0.93
    write_evaluation(summary, "table")
    out = capsys.readouterr().out
    assert "not estimable: ESS 4.6 of 3,000" in out
    assert "better than the logged behaviour by 0.019 [-0.004, 0.041] (FQE): not shown by " \
           "this log" in out
    assert "0.0000" not in out
