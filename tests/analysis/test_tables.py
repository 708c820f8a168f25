"""The tables' rows and columns: what a row answers is shown, what none answers is not."""

from stmpl.analysis.tables import table


def _row(**extra):
    return {"samples": 3, "rel_mee": (2.5, 0.5), "peak_err": (-1.25, 2.0), **extra}


def test_the_reaction_column_shows_where_a_row_answers_a_reaction():
    """A model given a pose answers the reaction: its error gets a column (a dash on the rows
    of predictors that answer none); a table of force models has no such column.
    """
    forces = table({"gnn": _row(), "naive": _row()})
    assert "reaction err %" not in forces
    posed = table({"gnn pose": _row(reaction_err=(-3.25, 1.5)), "naive": _row()})
    head, _, gnn, naive = posed.splitlines()[:4]
    column = [c.strip() for c in head.split("|")].index("reaction err %")
    assert [c.strip() for c in gnn.split("|")][column] == "-3.2 ± 1.5"
    assert [c.strip() for c in naive.split("|")][column] == "–"
    csv = table({"gnn pose": _row(reaction_err=(-3.25, 1.5))}, fmt="csv")
    assert "reaction_err_mean" in csv.splitlines()[0] and "-3.25" in csv.splitlines()[1]
