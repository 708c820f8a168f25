"""A fingertip on real tissue: a rigid sphere pressed into anny's left arm, depth by depth, with
the reaction force, the contact area, the peak pressure and the time of each depth.

    python benchmarks/press_forearm.py [--tissue forearm] [--radius-mm 8]
        [--depths-mm 1 2 3 4 6 8 10] [--res medium] [--subdivisions 0] [--weight 0.5]

The sphere starts touching the skin at chart point (0.45, 0.5) (mid-forearm) and is pushed
along the inward normal there; each depth starts from the last. Run it alone: the times are
wall-clock.
"""

from __future__ import annotations

import argparse
import time
import warnings

import numpy as np

from fem.contact import press
from fem.shapes import Sphere
from fem.simulate import resolution, tissue_mesh
from fem.solver import Solver
from stmpl import AnnyBody, loads, tissue
from stmpl.machine import describe
from stmpl.table import header, row


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--tissue", default="forearm", help="tissue preset (default forearm)")
    ap.add_argument("--radius-mm", type=float, default=8.0, help="the sphere's radius, mm")
    ap.add_argument(
        "--depths-mm", type=float, nargs="+", default=[1, 2, 3, 4, 6, 8, 10], help="mm, rising"
    )
    ap.add_argument("--res", default="medium", help="FEM resolution (default medium)")
    ap.add_argument("--subdivisions", type=int, default=0, help="the skin's subdivisions")
    ap.add_argument("--weight", type=float, default=0.5, help="anny weight phenotype")
    args = ap.parse_args()
    warnings.simplefilter("ignore")
    body = AnnyBody(phenotype={"weight": args.weight})
    part = body.part("left_arm").subdivided(args.subdivisions)
    thickness = tissue.from_weight(part, args.weight)
    disk = loads.disk(part, uv=(0.45, 0.5), radius=0.02, total=1.0)
    centre = part.vertices[disk.vertices].mean(0)
    at = disk.vertices[np.argmin(np.linalg.norm(part.vertices[disk.vertices] - centre, axis=1))]
    p, n = part.vertices[at], part.normals[at]
    t0 = time.perf_counter()
    mesh, material = tissue_mesh(part, thickness, args.res, args.tissue, near=p[None])
    solver = Solver(mesh, material, order=resolution(args.res).order)
    r = 1e-3 * args.radius_mm
    print(
        f"{args.tissue} on anny's left arm ({part.n_vertices} vertices), {args.radius_mm:g} mm "
        f"sphere; {len(solver.free)} DOFs, deepest {1e3 * mesh.thickness.max():.1f} mm of "
        f"tissue; set-up {time.perf_counter() - t0:.1f} s; {describe()}"
    )
    print(header(["depth mm", "reaction N", "area cm^2", "peak kPa", "s", "note"], "rrrrrl"))
    depths = [1e-3 * d for d in args.depths_mm]
    for answer in press(solver, Sphere(p + r * n, r), -n, depths):
        if not answer.ok:
            print(row([f"{1e3 * answer.depth:g}", "-", "-", "-", "-", answer.reason]))
            continue
        cells = [f"{1e3 * answer.depth:g}", f"{answer.reaction:.3f}"]
        cells += [f"{1e4 * answer.area:.2f}", f"{1e-3 * answer.pressure.max():.2f}"]
        print(row(cells + [f"{answer.time:.1f}", ""]), flush=True)


if __name__ == "__main__":
    main()
