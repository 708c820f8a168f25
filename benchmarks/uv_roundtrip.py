"""How much of an FEM answer the UV chart carries: the answer rasterised on the chart and sampled
back at the vertices, with no network between, at each image size.

    python benchmarks/uv_roundtrip.py [--data data/forearm_grips] [--splits test val]
        [--sizes 128 256 512]

The UV-UNet reads and writes the part's chart (:class:`stmpl.uv.UVMap`: a pixel takes its
triangle's barycentric blend of the vertex values, a vertex reads its four nearest pixel centres
bilinearly, a seam vertex's copies averaged). That round trip is exact for a field linear over
the chart, and loses where the field bends within a pixel: at a dent's deepest vertex every
pixel it reads lies on a slope down from it. For each sample of the splits, the FEM's
displacement goes round; printed are the mean and the largest error as a share of the sample's
peak (mean over the samples), the vertices where the largest errors fall, and how far inside the
object (the sample's gap at rest, negative inside) the worst one lies. A network trained on the
sampled vertices can make up for the loss with sharper images, which the bilinear reads of the
vertices next to a dent then see too.
"""

from __future__ import annotations

import argparse
import collections
import pathlib

import numpy as np
import torch

from stmpl.data.dataset import Dataset
from stmpl.table import header, row
from stmpl.uv import UVMap


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", default="data/forearm_grips")
    ap.add_argument("--splits", nargs="+", default=["test", "val"])
    ap.add_argument("--sizes", nargs="+", type=int, default=[128, 256, 512])
    args = ap.parse_args()

    ds = Dataset(pathlib.Path(args.data))
    a = ds.arrays()
    names = {"train": 0, "val": 1, "test": 2}
    keep = np.isin(a["split"], [names[s] for s in args.splits])
    u = a["displacement"][keep].astype(np.float64)
    gap = a["gap"][keep] if "gap" in a else None
    part = ds.part
    print(
        f"{args.data} ({', '.join(args.splits)}): {len(u)} samples on {part.name} "
        f"({part.n_vertices} vertices)"
    )
    print(
        header(
            ["px", "mean error % of peak", "largest % of peak", "worst vertices", "gap there mm"],
            "rrrll",
        )
    )
    for size in args.sizes:
        uv = UVMap(part, size)
        with torch.no_grad():
            back = uv.sample(uv.rasterise(torch.tensor(u, dtype=torch.float32))).double().numpy()
        err = np.linalg.norm(back - u, axis=2)
        peak = np.linalg.norm(u, axis=2).max(1, keepdims=True)
        moved = np.linalg.norm(u, axis=2) > 1e-6
        rel = err / peak
        mean = np.array([r[m].mean() for r, m in zip(rel, moved)])
        worst = rel.argmax(1)
        common = collections.Counter(worst.tolist()).most_common(3)
        gaps = "" if gap is None else f"{1e3 * np.median(gap[np.arange(len(u)), worst]):.1f}"
        print(
            row(
                [
                    str(size),
                    f"{100 * mean.mean():.3f}",
                    f"{100 * rel.max(1).mean():.1f} (up to {100 * rel.max():.1f})",
                    ", ".join(f"{v} ({c}x)" for v, c in common),
                    gaps,
                ]
            )
        )


if __name__ == "__main__":
    main()
