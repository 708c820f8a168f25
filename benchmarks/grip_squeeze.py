"""The squeeze each grip model answers as the hand closes, beside the FEM's: where force
control finds a grip's force, and why it misses some.

    python benchmarks/grip_squeeze.py [--split test] [--models NAME ...] [--to-mm 8]
                                      [--out docs/grip_squeeze.png]

For each grip of the shipped grip set's split (``data/forearm_grips``: a grip at one place and
fat thickness, solved by the FEM at 1, 2, 5 and 10 N), the hand is set at its first touch of
the skin (:func:`stmpl.contact.posing.first_touch`) and closed along its paths in steps of
0.5 mm (:func:`stmpl.contact.posing.moved`); at each step every model answers the pose and its
squeeze (the reaction, N) is read. The FEM's four answers are points: the force it carried and
how far past first touch the hand had closed. Prints, at each FEM point, each model's squeeze
at the FEM's depth (linear between the steps) over the FEM's, and draws each grip's curves.
One thread; nothing is timed, so it may run beside other jobs.
"""

from __future__ import annotations

import argparse
import os
import pathlib
import warnings

import numpy as np


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--split", default="test", choices=("train", "val", "test"))
    ap.add_argument(
        "--models",
        nargs="+",
        default=["linear_forearm_grips", "gnn_forearm_grips", "gnn_forearm_grips_fast"],
    )
    ap.add_argument("--to-mm", type=float, default=8.0, help="closing past first touch, mm")
    ap.add_argument("--out", default=None, help="PNG of the curves")
    args = ap.parse_args()
    os.environ.setdefault("OMP_NUM_THREADS", "1")
    warnings.simplefilter("ignore")  # the envelopes' notes on the grips

    from stmpl.contact.posing import first_touch, moved
    from stmpl.data.dataset import Dataset
    from stmpl.pipeline import zoo
    from stmpl.pipeline.evaluate import scenes_of
    from stmpl.table import header, row

    root = pathlib.Path(__file__).parents[1]
    ds = Dataset(root / "data" / "forearm_grips")
    a = ds.arrays()
    scenes, _ = scenes_of(ds, args.split, given="pose", way=True)
    index = np.flatnonzero(a["split"] == {"train": 0, "val": 1, "test": 2}[args.split])
    grips: dict[tuple, list] = {}
    for s, i in zip(scenes, index[: len(scenes)]):
        p = a["params"][i]
        key = (p["grip"], p["along"], p["around"], round(1e3 * float(a["thickness"][i].mean())))
        grips.setdefault(key, []).append((s, i))
    models = {n: zoo.read(n) for n in args.models}
    steps = np.arange(0.0, args.to_mm + 1e-9, 0.5)
    curves = {}
    print(f"{len(grips)} grips of data/forearm_grips ({args.split}), closed 0-{args.to_mm} mm")
    print(header(["grip", "FEM N", "FEM mm past touch", *[f"{n} / FEM" for n in models]]))
    for key, samples in grips.items():
        s0, i0 = samples[0]
        start = first_touch(s0.part, s0.thickness, a["kind"][i0], a["params"][i0])
        poses = [moved(start, 1e-3 * d) for d in steps]
        squeeze = {n: [float(m.predict(p).reaction) for p in poses] for n, m in models.items()}
        fem = sorted(
            (1e3 * (s.pose.depth - start.pose.depth), float(s.meta["reaction"])) for s, _ in samples
        )
        curves[key] = (squeeze, fem)
        name = f"{key[0]} at {key[1]}, {key[3]} mm"
        for depth, force in fem:
            at = [np.interp(depth, steps, squeeze[n]) / force for n in models]
            print(row([name, f"{force:.2f}", f"{depth:.2f}", *[f"{x:.2f}" for x in at]]))
    if args.out:
        _draw(curves, steps, list(models), args.out)
        print(f"wrote {args.out}")


def _draw(curves: dict, steps: np.ndarray, names: list, out: str) -> None:
    """One panel a grip: each model's squeeze against the closing, the FEM's answers as dots."""
    import matplotlib  # the chart only

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt  # the chart only

    fig, axes = plt.subplots(1, len(curves), figsize=(3.6 * len(curves), 3.4), sharey=True)
    axes = np.atleast_1d(axes)
    for ax, (key, (squeeze, fem)) in zip(axes, curves.items()):
        for n in names:
            ax.plot(steps, squeeze[n], label=n)
        d, f = zip(*fem)
        ax.plot(d, f, "ko", label="FEM")
        ax.set_title(f"{key[0]} at {key[1]} along, {key[3]} mm of fat", fontsize=9)
        ax.set_xlabel("closing past first touch (mm)")
        ax.grid(alpha=0.3)
    axes[0].set_ylabel("squeeze (N)")
    axes[0].legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(out, dpi=110)


if __name__ == "__main__":
    main()
