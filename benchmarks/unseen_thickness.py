"""The zoo's models on fresh FEM solves at thicknesses between (and off) the dataset's levels.

The datasets hold 5 / 6.25 / 7.5 / 8.75 / 10 mm; the linear FEM operator is computed at those
levels and interpolated between them, the learned models saw only them. Here: 5.5, 7, 8.1 and
9.5 mm, three disks each (0.2-0.4 N, radius 2-3 cm), solved by the FEM at the reference
resolution (not dataset samples). Prints each scene's relative MEE (%) and the means.

Run: python benchmarks/unseen_thickness.py   (about a minute on 2 cores)
"""

from __future__ import annotations

import numpy as np

from stmpl import AnnyBody, loads, predictor, tissue
from stmpl.metrics import sample_metrics
from stmpl.pipeline import zoo
from stmpl.scene import Scene
from stmpl.table import header, row

THICKNESS_M = (0.0055, 0.007, 0.0081, 0.0095)
DISKS = (((0.42, 0.55), 0.02, 0.2), ((0.3, 0.7), 0.025, 0.4), ((0.5, 0.45), 0.03, 0.3))


def main() -> None:
    arm = AnnyBody().part("left_arm")
    fem = predictor.create("fem")
    models = {n: zoo.read(n) for n in zoo.names()}
    print(header(["thickness mm", "load", *models], "ll" + "r" * len(models)))
    rows = []
    for t in THICKNESS_M:
        for uv, r, total in DISKS:
            s = Scene.from_load(
                arm, tissue.constant(arm, t), loads.disk(arm, uv=uv, radius=r, total=total)
            )
            truth = fem.predict(s).displacement
            rel = {
                n: sample_metrics(truth, m.predict(s).displacement)["rel_mee"]
                for n, m in models.items()
            }
            rows.append(rel)
            cells = [f"{v:.2f}" for v in rel.values()]
            print(row([f"{t * 1e3:g}", f"disk {r * 100:g} cm, {total:g} N", *cells]), flush=True)
    print(row(["mean", "", *(f"{np.mean([r[n] for r in rows]):.2f}" for n in models)]))


if __name__ == "__main__":
    main()
