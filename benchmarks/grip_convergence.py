"""How far a grip's answer moves with the size of the region its mesh is refined in: one task of
a grip config solved from rest through its forces with the mesh refined once more within each
of two radii of where the closed hand reaches, the answers compared on the skin's vertices.

    python benchmarks/grip_convergence.py [--config configs/data/forearm_grips.yaml] [--task 4]
                                          [--forces 1 5] [--radii 0.03 0.01]

The first radius is the reference. The default (the pinch at 0.3 of anny's left arm on 5 mm of
skin and fat, to 1 and then 5 N, within 3 and 1 cm) takes about 40 minutes of one core for the
two; run it on one thread (``OMP_NUM_THREADS=1 MKL_NUM_THREADS=1``), as the dataset's workers
run. The times are each solve's own, as the dataset records them.
"""

from __future__ import annotations

import argparse
import json
import time

import numpy as np


def solve(cfg: dict, task: int, radius: float) -> dict:
    """The task's samples with the mesh refined within ``radius`` (m), and the seconds taken."""
    from fem.config import read_config
    from fem.placements import plan
    from fem.worker import payload, solve_shard

    res = {"subdivisions": 1, "layers": 1, "refine_radius": radius, "order": 2}
    p = plan(read_config({**cfg, "resolution": res}))
    shard = next(k for k in range(p.n_shards) if task in p.shard_tasks(k))
    t0 = time.perf_counter()
    out = solve_shard(payload(p, shard, 1))
    rec = out["records"]
    if out["failures"]:
        raise SystemExit(f"within {radius:g} m: {out['failures']}")
    return {
        "displacement": np.stack(rec["displacement"]),
        "total": np.asarray(rec["total"]),
        "depth": np.asarray([json.loads(s)["depth"] for s in rec["params"]]),
        "solve_time": np.asarray(rec["solve_time"]),
        "wall": time.perf_counter() - t0,
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--config", default="configs/data/forearm_grips.yaml")
    ap.add_argument("--task", type=int, default=4)
    ap.add_argument("--forces", type=float, nargs="+", default=[1.0, 5.0])
    ap.add_argument("--radii", type=float, nargs=2, default=[0.03, 0.01])
    args = ap.parse_args()

    from fem.config import read_config
    from stmpl.machine import describe
    from stmpl.metrics import sample_metrics
    from stmpl.table import header, row

    cfg = {**read_config(args.config), "forces": args.forces}
    ref, other = (solve(cfg, args.task, r) for r in args.radii)
    print(f"{args.config}: task {args.task}, refined within {args.radii[0]:g} m (reference)")
    print(f"and {args.radii[1]:g} m; {describe()}")
    cols = ["N", "depth mm", "depth %", "peak %", "relative MEE %", "s", "s (reference)"]
    print(header(cols, "rrrrrrr"))
    for i, f in enumerate(ref["total"]):
        m = sample_metrics(ref["displacement"][i], other["displacement"][i])
        print(
            row(
                [
                    f"{f:g}",
                    f"{1e3 * other['depth'][i]:.4f}",
                    f"{100 * (other['depth'][i] / ref['depth'][i] - 1):+.2f}",
                    f"{m['peak_err']:+.2f}",
                    f"{m['rel_mee']:.2f}",
                    f"{other['solve_time'][i]:.0f}",
                    f"{ref['solve_time'][i]:.0f}",
                ]
            )
        )


if __name__ == "__main__":
    main()
