"""The reaction under mesh refinement: a rigid 8 mm sphere pressed into the forearm preset on an
arm-sized tube (radius 35 mm, 7.5 mm of skin and fat over the muscle), the skin refined 1, 2
and 3 times within 2 cm of the contact (quadratic tetrahedra, the preset's element layers).

    python benchmarks/press_convergence.py [--depths-mm 2 4] [--levels 1 2 3] [--tissue forearm]

A second table gives, per depth, the change between the two finest meshes beside the smallest
volume ratio (min det F) and the compression (how far the skin moves in, as a share of the
tissue's depth) of the finest: where the change stays small the answer is converged, which is
how the presets' trust bounds were measured (the presets' own bounds are lifted here, so the
run sees past them). Run it alone: the times are wall-clock (the finest mesh takes about five
minutes).
"""

from __future__ import annotations

import argparse
import time
import warnings
from dataclasses import replace

import numpy as np

from fem.contact import press
from fem.kinematics import det3
from fem.layers import preset
from fem.shapes import Sphere
from fem.simulate import tissue_mesh
from fem.solver import Solver
from fem.verification import arm_tube
from stmpl.machine import describe
from stmpl.table import header, row


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--depths-mm", type=float, nargs="+", default=[2.0, 4.0])
    ap.add_argument("--levels", type=int, nargs="+", default=[1, 2, 3])
    ap.add_argument("--tissue", default="forearm")
    args = ap.parse_args()
    warnings.simplefilter("ignore")
    part, thickness, p, n = arm_tube()
    depths = [1e-3 * d for d in args.depths_mm]
    print(f"{args.tissue} on a tube, 8 mm sphere; {describe()}")
    columns = ["skin refinements", "DOFs", *(f"reaction at {d:g} mm, N" for d in args.depths_mm)]
    print(header(columns + ["s"], "r" * (len(columns) + 1)))
    stack = preset(args.tissue)
    if stack is not None:
        stack = replace(stack, limits=None)
    runs, where = [], []
    for level in args.levels:
        res = {"subdivisions": level, "layers": 2, "refine_radius": 0.02, "order": 2}
        t0 = time.perf_counter()
        mesh, material = tissue_mesh(part, thickness, res, stack or "paper", near=p[None])
        solver = Solver(mesh, material, order=2)
        out = press(solver, Sphere(p + 0.008 * n, 0.008), -n, depths)
        runs.append(out)
        where.append([weakest(solver, r) for r in out])
        cells = [f"{r.reaction:.4f}" if r.ok else r.reason for r in out]
        seconds = f"{time.perf_counter() - t0:.0f}"
        print(row([level, len(solver.free), *cells, seconds]), flush=True)
    if len(runs) < 2:
        return
    print()
    columns = ["depth mm", "change, last refinement", "min det F", "in", "compression"]
    print(header(columns, "rrrlr"))
    for d, coarse, fine, layer in zip(args.depths_mm, runs[-2], runs[-1], where[-1]):
        if not (coarse.ok and fine.ok):
            print(row([f"{d:g}", (fine if coarse.ok else coarse).reason, "-", "-", "-"]))
            continue
        change = f"{100 * (fine.reaction / coarse.reaction - 1):+.1f} %"
        cells = [f"{d:g}", change, f"{fine.min_det_F:.3f}", layer, f"{fine.compression:.2f}"]
        print(row(cells))


def weakest(solver, answer) -> str:
    """The tissue layer where ``answer`` keeps the least of its volume (``-`` if it failed)."""
    if not answer.ok:
        return "-"
    J = det3(solver._F(answer.state))
    layer = getattr(solver.material, "layer", None)
    if layer is None:
        return "gel"
    at = np.repeat(np.asarray(layer), len(J) // len(layer))[np.argmin(J)]
    return ("skin", "fat", "muscle")[at] if at < 3 else f"layer {at}"


if __name__ == "__main__":
    main()
