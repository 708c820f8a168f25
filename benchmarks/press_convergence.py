"""The reaction under mesh refinement: a rigid 8 mm sphere pressed into the forearm preset on an
arm-sized tube (radius 35 mm, 7.5 mm of skin and fat over the muscle), the skin refined 1, 2
and 3 times within 2 cm of the contact (quadratic tetrahedra, the preset's element layers).

    python benchmarks/press_convergence.py [--depths-mm 2 4] [--levels 1 2 3]

Run it alone: the times are wall-clock (the finest mesh takes about five minutes).
"""

from __future__ import annotations

import argparse
import time
import warnings

from fem.contact import press
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
    for level in args.levels:
        res = {"subdivisions": level, "layers": 2, "refine_radius": 0.02, "order": 2}
        t0 = time.perf_counter()
        mesh, material = tissue_mesh(part, thickness, res, args.tissue, near=p[None])
        solver = Solver(mesh, material, order=2)
        out = press(solver, Sphere(p + 0.008 * n, 0.008), -n, depths)
        cells = [f"{r.reaction:.4f}" if r.ok else r.reason for r in out]
        seconds = f"{time.perf_counter() - t0:.0f}"
        print(row([level, len(solver.free), *cells, seconds]), flush=True)


if __name__ == "__main__":
    main()
