import csv as stdcsv
import io

import pytest

from stmpl import table


def test_markdown_lays_out_header_rule_and_rows():
    md = table.markdown(["model", "ms"], [["gnn", "3.1"], ["naive", "0.3"]], "lr")
    assert md.splitlines() == [
        "| model | ms |",
        "| --- | --: |",
        "| gnn | 3.1 |",
        "| naive | 0.3 |",
    ]
    assert table.header(["a", "b", "c"], "r").splitlines()[1] == "| --: | --- | --- |"


def test_csv_round_trips_cells_that_need_quoting():
    text = table.csv(["set-up", "n"], [['GNN, "auto"', "3"]])
    assert list(stdcsv.reader(io.StringIO(text))) == [["set-up", "n"], ['GNN, "auto"', "3"]]


@pytest.mark.parametrize(
    "columns, rows, align, message",
    [
        ([], [], "", "at least one column"),
        (["a", "b"], [["1"]], "", "row 0 has 1 cells, the header 2 columns"),
        (["a"], [["1"]], "x", "l/r letters"),
        (["a"], [["1"]], "lr", "l/r letters"),
    ],
)
def test_a_malformed_table_is_refused_by_name(columns, rows, align, message):
    with pytest.raises(ValueError, match=message):
        table.markdown(columns, rows, align)
