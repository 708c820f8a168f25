"""The speed-vs-accuracy chart: the Pareto front and the files."""

import numpy as np

from stmpl.viz.chart import family, pareto, speed_accuracy


def test_pareto_front_keeps_the_unbeaten():
    x = np.array([1.0, 2.0, 3.0, 0.5, 2.5])
    y = np.array([5.0, 1.0, 0.5, 9.0, 2.0])  # (2.5, 2.0) is beaten by (2.0, 1.0)
    assert pareto(x, y).tolist() == [3, 0, 1, 2]


def test_families_and_files(tmp_path):
    assert [
        family(n) for n in ("GNN: only 3", "linear FEM", "FEM (coarse)", "UV-UNet", "Naive", "x")
    ] == ["GNN", "linear FEM", "FEM", "UV-UNet", "Naive", "other"]
    err = {"rel_mee": 0.5, "ci": 0.05, "peak_err": 2.0}
    pts = [
        {
            "label": "GNN",
            "batch": 1,
            "seconds": 2e-3,
            "spread": (1.8e-3, 2.5e-3),
            "in": err,
            "out": err,
        },
        {"label": "GNN", "batch": 64, "seconds": 2e-4, "spread": None, "in": err, "out": err},
        {
            "label": "FEM (coarse)",
            "batch": 1,
            "seconds": 3.0,
            "spread": (2.0, 4.0),
            "in": {"rel_mee": 2.0, "ci": 0.3},
            "out": None,
        },
        {
            "label": "FEM (the truth)",
            "batch": 1,
            "seconds": 5.0,
            "spread": (4.0, 6.0),
            "truth": True,
            "in": None,
            "out": None,
        },
    ]
    files = speed_accuracy(pts, tmp_path / "c")
    assert [f.suffix for f in files] == [".png", ".svg"] and files[0].stat().st_size > 20_000
    svg = files[1].read_text()
    for words in ("in distribution", "out of distribution", "batch 64", "the truth", "84 ± 53 s"):
        assert words in svg, words


def test_names_do_not_overlap_one_another():
    """A crowd of points (the paper ablation's cluster) and a slow one at the right edge whose
    name the leader-line column would cover: every point is named once, no two names touch.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.text import Text

    from stmpl.viz.chart import _labels

    fig, ax = plt.subplots(figsize=(6.5, 4.5), dpi=130)
    rng = np.random.default_rng(0)
    items = [
        (float(x), float(y), f"set-up {i}")
        for i, (x, y) in enumerate(
            zip(10 ** rng.uniform(0.2, 1.7, 14), 10 ** rng.uniform(-0.45, -0.2, 14))
        )
    ]
    items += [(1900.0, 0.88, "FEM (medium mesh)"), (2100.0, 2.2, "FEM (coarse mesh)")]
    ax.scatter([i[0] for i in items], [i[1] for i in items])
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlim(0.1, 2100 * 6)
    ax.set_ylim(0.2, 3)
    _labels(ax, items)
    fig.canvas.draw()
    r = fig.canvas.get_renderer()
    names = [t for t in ax.texts]
    assert sorted(t.get_text() for t in names) == sorted(i[2] for i in items)
    boxes = [Text.get_window_extent(t, r) for t in names]
    clashes = [
        (names[i].get_text(), names[j].get_text())
        for i in range(len(boxes))
        for j in range(i)
        if boxes[i].overlaps(boxes[j])
    ]
    plt.close(fig)
    assert not clashes
