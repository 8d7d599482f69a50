"""The explain tables (aoc_cli/report/explain_view.py): the subset's rows as records."""

from aoc_cli.cli.explain_view import _support_rows


def _row(value):
    return {"row": 3, "episode": 1, "episode_id": "p1", "step": 2, "tags": {"clinician": "c1"},
            "action": 1, "value": value, "weight": 0.5, "distance": 0.1, "episodes_here": 1}


def test_value_column_only_where_a_row_has_a_value():
    imitation = _support_rows([_row(None), _row(None)])
    assert "value" not in imitation[0] and list(imitation[0])[-3:] == ["weight", "distance",
                                                                       "episodes here"]
    valued = _support_rows([_row(None), _row(0.25)])
    assert [r["value"] for r in valued] == [None, 0.25]


def test_each_rows_label_of_the_action_shown_beside_its_weight():
    rows = [dict(_row(None), label=[0.3, 0.7], weight=0.000702506, distance=0.4069491),
            dict(_row(None), label=[0.9, 0.1], episode_id=None)]
    table = _support_rows(rows, 1)
    assert [r["label"] for r in table] == [0.7, 0.1]      # the label of action 1, the decided
    assert table[0]["weight"] == 0.000703 and table[0]["distance"] == 0.407
    assert list(table[0])[-4:] == ["weight", "label", "distance", "episodes here"]
    # the episode's own id where it has one, else its number
    assert table[0]["episode_id"] == "p1" and "episode" not in table[0]
    assert table[1]["episode"] == 1 and "episode_id" not in table[1]
    assert [r["label"] for r in _support_rows(rows, 0)] == [0.3, 0.9]
