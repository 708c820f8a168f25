"""How many element layers each tissue layer needs: a rigid 8 mm sphere pressed into the
forearm preset of an arm-sized tube (as ``press_convergence.py``, the skin refined twice near
the contact), with one layer's element count raised at a time from the preset's (skin 1, fat 2,
muscle 2; quadratic tetrahedra).

    python benchmarks/layer_convergence.py [--depths-mm 2 4] [--tissue forearm]
        [--counts muscle=1 fat=1]

Each row changes one count; the reactions are compared with the preset's row. ``--counts``:
the preset's row and these in place of the default ones (fewer elements: a cheaper mesh). Run
it alone: the times are wall-clock.
"""

from __future__ import annotations

import argparse
import time
import warnings
from dataclasses import replace

from fem.contact import press
from fem.layers import preset
from fem.shapes import Sphere
from fem.simulate import tissue_mesh
from fem.solver import Solver
from fem.verification import arm_tube
from stmpl.machine import describe
from stmpl.table import header, row

VARIANTS = [{}, {"skin": 2}, {"skin": 3}, {"fat": 4}, {"muscle": 4}]
"""Element counts changed from the preset's, a row each (the first: the preset itself)."""


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--depths-mm", type=float, nargs="+", default=[2.0, 4.0])
    ap.add_argument("--tissue", default="forearm")
    ap.add_argument("--counts", nargs="+", metavar="LAYER=N", help="rows to run, e.g. muscle=1")
    args = ap.parse_args()
    variants = VARIANTS if not args.counts else [{}] + [_count(c) for c in args.counts]
    warnings.simplefilter("ignore")
    part, thickness, p, n = arm_tube()
    depths = [1e-3 * d for d in args.depths_mm]
    base = preset(args.tissue)
    print(f"{args.tissue} on a tube, 8 mm sphere, skin refined twice; {describe()}")
    columns = ["elements (skin, fat, muscle)", "DOFs"]
    columns += [f"reaction at {d:g} mm, N (change)" for d in args.depths_mm]
    print(header(columns + ["s"], "l" + "r" * (len(columns))))
    reference = None
    for change in variants:
        layers = tuple(replace(x, elements=change.get(x.name, x.elements)) for x in base.layers)
        stack = replace(base, layers=layers)
        res = {"subdivisions": 2, "layers": 2, "refine_radius": 0.02, "order": 2}
        t0 = time.perf_counter()
        mesh, material = tissue_mesh(part, thickness, res, stack, near=p[None])
        solver = Solver(mesh, material, order=2)
        out = press(solver, Sphere(p + 0.008 * n, 0.008), -n, depths)
        forces = [r.reaction if r.ok else float("nan") for r in out]
        reference = reference or forces
        cells = [
            f"{f:.4f} ({100 * (f / r0 - 1):+.1f} %)" if r.ok else r.reason
            for f, r0, r in zip(forces, reference, out)
        ]
        counts = ", ".join(str(x.elements) for x in layers)
        seconds = f"{time.perf_counter() - t0:.0f}"
        print(row([counts, len(solver.free), *cells, seconds]), flush=True)


def _count(text: str) -> dict:
    """``{"muscle": 1}`` from ``"muscle=1"``."""
    name, _, n = text.partition("=")
    if name not in ("skin", "fat", "muscle") or not n.isdigit() or int(n) < 1:
        raise SystemExit(f"--counts takes LAYER=N (skin, fat or muscle; N >= 1), got {text!r}")
    return {name: int(n)}


if __name__ == "__main__":
    main()
