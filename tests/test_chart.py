"""The speed-vs-accuracy chart: the Pareto front and the files."""

import numpy as np

from stmpl.chart import family, pareto, speed_accuracy


def test_pareto_front_keeps_the_unbeaten():
    x = np.array([1.0, 2.0, 3.0, 0.5, 2.5])
    y = np.array([5.0, 1.0, 0.5, 9.0, 2.0])       # (2.5, 2.0) is beaten by (2.0, 1.0)
    assert pareto(x, y).tolist() == [3, 0, 1, 2]


def test_families_and_files(tmp_path):
    assert [family(n) for n in ("GNN: only 3", "linear FEM", "FEM (coarse)", "UV-UNet",
                                "Naive", "x")] == ["GNN", "linear FEM", "FEM", "UV-UNet",
                                                   "Naive", "other"]
    pts = [{"label": "GNN", "batch": 1, "seconds": 2e-3, "rel_mee": 0.5, "peak_err": 2.0},
           {"label": "GNN", "batch": 64, "seconds": 2e-4, "rel_mee": 0.5, "peak_err": 2.0},
           {"label": "FEM (coarse)", "batch": 1, "seconds": 3.0, "rel_mee": 2.0,
            "peak_err": -8.0}]
    files = speed_accuracy(pts, tmp_path / "c")
    assert [f.suffix for f in files] == [".png", ".svg"] and files[0].stat().st_size > 20_000
