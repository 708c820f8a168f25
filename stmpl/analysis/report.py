"""The ablation's report (:mod:`stmpl.analysis.ablation`): its markdown, its tables as markdown
and CSV, and its speed-against-accuracy chart.
"""

from __future__ import annotations

import pathlib

from stmpl.analysis.tables import HONESTY, PAPER, TITLES, table
from stmpl.files import atomic_write_text
from stmpl.machine import describe
from stmpl.metrics import honesty
from stmpl.table import markdown
from stmpl.viz.chart import speed_accuracy

POOLED = "pooled out of distribution"
"""Table 2's row of a set-up over every out-of-distribution set together (as the paper's)."""


def write(
    cfg,
    tables,
    out: pathlib.Path,
    points: list,
    remade: dict | None = None,
    cost: dict | None = None,
    chart: bool = True,
) -> None:
    """Write the ablation's report into ``out``: ``ablation.md`` (the datasets, the machine,
    the compute, the tables, the honesty of the answers, the speed table) and each table as
    ``.md`` and ``.csv``; with ``chart``, the speed-against-accuracy chart of ``points`` too.
    """
    parts = [
        f"# Ablation: {cfg['name']}\n",
        "Datasets: "
        + ", ".join(f"{n} ({d['folder']})" for n, d in cfg["datasets"].items())
        + f". Machine: {describe()}. Errors in mm on the vertices that move more "
        "than 0.001 mm, mean ± std over samples; rel. MEE against each sample's largest "
        "displacement; peak err: predicted against true largest displacement, signed. "
        "Rows in italics are the paper's as reported (its data, not ours).\n",
    ]
    if cost:
        parts.append(
            f"Compute behind this report: training {cost['train'] / 60:.0f} min, "
            f"evaluation {cost['evaluate'] / 60:.0f} min (summed over the runs that "
            f"made the cached results); this run took {cost['wall'] / 60:.1f} min, "
            "the rest came from the cache.\n"
        )
    for n, v in (remade or {}).items():
        parts.append(
            f"Dataset {n} was made again (content hash {v['hash']}, not the recorded "
            f"one): {v['checked_with']} measures {v['rel_mee'][1]:.4f} % / "
            f"{v['peak_err'][1]:+.2f} % on it against {v['rel_mee'][0]:.4f} % / "
            f"{v['peak_err'][0]:+.2f} % on the recorded set ({v['samples'][1]} test "
            "samples), so the rows measured on the recorded set stand; rows measured "
            "since are on the remade one.\n"
        )
    for k, rows in tables.items():
        if not rows:
            continue
        paper = PAPER[k]
        atomic_write_text(out / f"{k}.md", table(rows, paper))
        atomic_write_text(out / f"{k}.csv", table(rows, paper, "csv"))
        parts.append(f"## {TITLES[k]}\n\n" + table(rows, paper))
    judged = {**tables.get("table1", {}), **tables.get("table2", {})}
    judged = {k: v for k, v in judged.items() if not k.endswith(f" / {POOLED}")}
    if judged:
        parts.append(HONESTY + honesty(judged))
    if points:
        if chart:
            speed_accuracy(
                [p for p in points if p.get("chart", True)],
                out / "speed_accuracy",
                f"Speed against accuracy ({cfg['name']}): lower left is better",
            )
        speeds = markdown(
            [
                "set-up",
                "batch",
                "ms/scene (quartiles)",
                "rel. MEE % in distribution",
                "OOD rel. MEE %",
                "OOD peak err %",
            ],
            [speed_row(p) for p in points],
            "lrrrrr",
        )
        parts.insert(
            2 + bool(cost),
            "## Speed against accuracy\n\n![speed against accuracy]"
            "(speed_accuracy.png)\n\nTime per scene on this machine at batch 1 and "
            "64: the median over repeats, the bars its quartiles (the FEM: 3 scenes solved "
            "one at a time, from rest). Error: the relative MEE in distribution and pooled "
            "over the out-of-distribution test sets, the bars the 95 % interval of its mean "
            "over the test scenes (rel. MEE ± that half-width below). Circles are batch 1, "
            "squares batch 64, each with its own Pareto front. The FEM at the mesh the data "
            "was made at is the truth (no error of its own) and sits on the panels' floor "
            "with the paper's FEM time (its CPU, one thread, as reported); the star is the "
            "paper's reported UV-UNet (its GPU, its data), a reference, not our "
            "measurement.\n\n" + speeds,
        )
    atomic_write_text(out / "ablation.md", "\n".join(parts))


def speed_row(p: dict) -> list[str]:
    """A row of the report's speed table."""
    ms = f"{1e3 * p['seconds']:.3g}"
    if p.get("spread"):
        ms += f" ({1e3 * p['spread'][0]:.3g}-{1e3 * p['spread'][1]:.3g})"
    if p.get("truth"):
        return [p["label"], str(p["batch"]), ms, "the truth", "the truth", "–"]

    def err(e):
        return "–" if e is None else f"{e['rel_mee']:.2f} ± {e['ci']:.2f}"

    peak = "–" if p["out"] is None else f"{p['out']['peak_err']:+.1f}"
    return [p["label"], str(p["batch"]), ms, err(p["in"]), err(p["out"]), peak]
