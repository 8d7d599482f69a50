"""The explain tables (aoc_cli/report/explain_view.py): the subset's rows as records."""

from aoc_cli.report.explain_view import _support_rows


def _row(value):
    return {"row": 3, "episode": 1, "episode_id": "p1", "step": 2, "tags": {"clinician": "c1"},
            "action": 1, "value": value, "weight": 0.5, "distance": 0.1, "episodes_here": 1}


def test_value_column_only_where_a_row_has_a_value():
    imitation = _support_rows([_row(None), _row(None)])
    assert "value" not in imitation[0] and list(imitation[0])[-3:] == ["weight", "distance",
                                                                       "episodes here"]
    valued = _support_rows([_row(None), _row(0.25)])
    assert [r["value"] for r in valued] == [None, 0.25]
