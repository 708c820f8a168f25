"""UV raster speed on the anny left arm: build, rasterise and sample at 64..512 px.

Run: python benchmarks/uv_speed.py [--batch 64] [--repeat 50]
Target: rasterising the arm at 512x512 in under 50 ms on a 2-core CPU.
"""

from __future__ import annotations

import argparse
import time

import numpy as np
import torch
from _timing import median_time

from stmpl.body import AnnyBody
from stmpl.machine import describe
from stmpl.uv import UVMap


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--batch", type=int, default=64)
    ap.add_argument("--repeat", type=int, default=30)
    args = ap.parse_args()
    torch.manual_seed(0)
    part = AnnyBody().part("left_arm")
    print(f"machine: {describe()}")
    print(f"part: left_arm, {part.n_vertices} vertices, {part.n_faces} faces")
    print(
        f"{'size':>5} {'build ms':>9} {'rast ms':>8} {'samp ms':>8} "
        f"{'rast B ms':>10} {'samp B ms':>10} {'B':>3} {'round-trip err %':>17}"
    )
    x = part.vertices
    field = torch.tensor(
        np.stack([np.sin(20 * x[:, 0]) + np.cos(15 * x[:, 2]), 10 * x[:, 1]], 1),
        dtype=torch.float32,
    )
    batch = torch.rand(args.batch, part.n_vertices, 2)
    rows = []
    for size in (64, 128, 256, 512):
        s = time.perf_counter()
        m = UVMap(part, size)
        build = time.perf_counter() - s
        img = m.rasterise(field)
        imgs = m.rasterise(batch)
        with torch.no_grad():
            r1 = median_time(lambda: m.rasterise(field), args.repeat)
            s1 = median_time(lambda: m.sample(img), args.repeat)
            rb = median_time(lambda: m.rasterise(batch), max(3, args.repeat // 5))
            sb = median_time(lambda: m.sample(imgs), max(3, args.repeat // 5))
        err = (
            (m.sample(img) - field).abs().max(0).values
            / (field.max(0).values - field.min(0).values)
        ).max().item() * 100
        rows.append((size, r1))
        print(
            f"{size:>5} {build * 1e3:>9.1f} {r1 * 1e3:>8.2f} {s1 * 1e3:>8.3f} "
            f"{rb * 1e3:>10.1f} {sb * 1e3:>10.2f} {args.batch:>3} {err:>17.3f}"
        )
    r512 = dict(rows)[512]
    print(
        f"target: rasterise 512x512 < 50 ms -> {r512 * 1e3:.2f} ms "
        f"({50e-3 / r512:.0f}x under the target)"
    )


if __name__ == "__main__":
    main()
