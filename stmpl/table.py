"""Tables as text: the one writer of every markdown and CSV table stmpl prints or saves.

A table is a header (column names) and rows of cells already formatted as strings; the callers
(:func:`stmpl.metrics.table`, the ablation's tables, the zoo's list, the stability sweep, the
benchmarks) decide what goes in a cell, this module how the cells are laid out.
"""

from __future__ import annotations

import csv as _csv
import io
from collections.abc import Sequence


def _checked(header: Sequence[str], rows: Sequence[Sequence[str]]) -> list[list[str]]:
    if not header:
        raise ValueError("a table needs at least one column")
    out = []
    for k, row in enumerate(rows):
        row = [str(c) for c in row]
        if len(row) != len(header):
            raise ValueError(f"row {k} has {len(row)} cells, the header {len(header)} columns")
        out.append(row)
    return out


def header(columns: Sequence[str], align: str = "") -> str:
    """A markdown table's first two lines: the column names and the rule under them. ``align``
    has one letter per column, ``l`` (left, the default for columns it does not reach) or ``r``
    (right: numbers). A long run prints :func:`header` once, then a :func:`row` per result as it
    comes.
    """
    if not columns:
        raise ValueError("a table needs at least one column")
    if any(a not in "lr" for a in align) or len(align) > len(columns):
        raise ValueError(f"align must be l/r letters, at most one per column, got {align!r}")
    rule = ["--:" if a == "r" else "---" for a in align.ljust(len(columns), "l")]
    return row(columns) + "\n" + row(rule)


def row(cells: Sequence) -> str:
    """One markdown table row of ``cells`` (each written with ``str``)."""
    return "| " + " | ".join(str(c) for c in cells) + " |"


def markdown(columns: Sequence[str], rows: Sequence[Sequence], align: str = "") -> str:
    """A markdown table: :func:`header` and a :func:`row` per entry of ``rows``."""
    cells = _checked(columns, rows)
    return "\n".join([header(columns, align), *(row(r) for r in cells)]) + "\n"


def csv(header: Sequence[str], rows: Sequence[Sequence[str]]) -> str:
    """A CSV table (cells quoted where they need it)."""
    cells = _checked(header, rows)
    buf = io.StringIO()
    w = _csv.writer(buf, lineterminator="\n")
    w.writerow(header)
    w.writerows(cells)
    return buf.getvalue()
