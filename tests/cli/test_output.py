"""Tables round floats for reading, also inside action vectors; CSV and JSON keep every digit."""

import json

from aoc_cli.cli.output import write_object, write_records


def test_table_rounds_vectors_and_csv_keeps_full_precision(capsys):
    record = {"action": [0.7424028930074971, -1.23456789e-9], "tags": {"policy": "pi2"},
              "value": -1.0238312345}
    write_records([record], "table")
    table = capsys.readouterr().out
    assert "[0.742403, -1.23457e-09]" in table and "-1.02383" in table
    assert "{policy: \"pi2\"}" in table and "0.7424028930074971" not in table
    write_records([record], "csv")
    csv_text = capsys.readouterr().out
    assert "[0.7424028930074971,-1.23456789e-09]" in csv_text
    write_object(record, "json")
    assert json.loads(capsys.readouterr().out) == record
