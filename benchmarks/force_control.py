"""Force control two ways on the layered forearm preset: the depth solved with the displacement
in one Newton system, against the search over depths, side by side in one run.

    python benchmarks/force_control.py [--object ball|disk] [--forces 0.5 2 5 10]
        [--around 16] [--along 8] [--subdivisions 0]

A tube of 5 cm radius (``--around`` x ``--along`` vertices, subdivided ``--subdivisions``
times: the press is meshed on the part it came from, `fem.finer`) under 10 mm of skin and fat
over the preset's muscle, at `medium`; an 8 mm ball or a 10 mm disk (its rim rounded by 1 mm)
placed at first contact at the tube's middle and pushed along the inward normal to each force
in turn, each from the last one's answer (as a dataset's press task does), first by the
search (`coupled=False`), then in one Newton system. Per force: the reaction, the depth, the
Newton iterations (tangents assembled), the factorisations and the seconds; then each coupled
answer against a press from rest to the depth it found. Run it alone: the times are
wall-clock.
"""

from __future__ import annotations

import argparse
import time
import warnings

import numpy as np

from fem.contact import press
from fem.force_control import press_to_forces
from fem.shapes import Punch, Sphere, skin_near, touching
from fem.simulate import press_solver
from stmpl.body import tube
from stmpl.machine import describe
from stmpl.table import header, row


def counting(solver) -> dict:
    """Count the solver's tangent assemblies and factorisations (wrapped on the instance)."""
    seen = {"assembled": 0, "factorised": 0}
    assemble, factor = solver.assemble, solver.linear.factor

    def assembled(*a, **k):
        seen["assembled"] += 1
        return assemble(*a, **k)

    def factorised(*a, **k):
        seen["factorised"] += 1
        return factor(*a, **k)

    solver.assemble, solver.linear.factor = assembled, factorised
    solver.tangent.assemble = assembled
    return seen


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--object", choices=("ball", "disk"), default="ball")
    ap.add_argument("--forces", type=float, nargs="+", default=[0.5, 2.0, 5.0, 10.0], help="N")
    ap.add_argument("--around", type=int, default=16, help="the tube's vertices around")
    ap.add_argument("--along", type=int, default=8, help="the tube's vertices along")
    ap.add_argument("--subdivisions", type=int, default=0, help="the tube's subdivisions")
    args = ap.parse_args()
    warnings.simplefilter("ignore")
    coarse = tube(0.05, 0.08, args.around, args.along)
    part = coarse.subdivided(args.subdivisions)
    at = int(np.argmin(np.linalg.norm(coarse.vertices - [0.05, 0.0, 0.04], axis=1)))
    p, n = coarse.vertices[at], coarse.normals[at]
    if args.object == "ball":
        shape = touching(Sphere(p + 0.008 * n, 0.008), -n, skin_near(coarse, p, 0.024))
    else:
        shape = touching(Punch(p + 0.002 * n, -n, 0.01, 0.001), -n, skin_near(coarse, p, 0.03))
    thickness = np.full(part.n_vertices, 0.010)
    print(f"{args.object} on the forearm preset of a tube; {describe()}")
    print(
        header(
            ["way", "force N", "reaction N", "depth mm", "iterations", "factorised", "s"],
            "lrrrrrr",
        )
    )
    answers = {}
    for coupled in (False, True):
        solver = press_solver(part, thickness, "medium", "forearm", None, p[None])
        seen = counting(solver)
        way = "one system" if coupled else "search"
        last, t0 = dict(seen), time.perf_counter()

        def report(force, answer, way=way, seen=seen, last=last):
            now = time.perf_counter()
            cells = [way, f"{force:g}"]
            if answer.ok:
                cells += [f"{answer.reaction:.4f}", f"{1e3 * answer.depth:.3f}"]
            else:
                cells += ["failed", answer.reason[:40]]
            cells += [str(seen[k] - last[k]) for k in ("assembled", "factorised")]
            print(row([*cells, f"{now - last['t']:.1f}"]), flush=True)
            last.update(seen, t=now)

        last["t"] = t0
        answers[coupled] = press_to_forces(solver, shape, -n, args.forces, report, coupled=coupled)
        print(
            f"{way}: {time.perf_counter() - t0:.0f} s in all, {3 * solver.n_all} DOFs",
            flush=True,
        )
    print("\none system's answers against a press from rest to the depth each found:")
    for answer in answers[True]:
        if answer.ok:
            (same,) = press(solver, shape, -n, [answer.depth])
            peak = np.linalg.norm(same.displacement, axis=1).max()
            off = np.abs(answer.displacement - same.displacement).max() / peak
            print(
                f"  {1e3 * answer.depth:.3f} mm: reaction {same.reaction:.4f} N against "
                f"{answer.reaction:.4f}; displacement within {off:.1e} of the deepest"
            )


if __name__ == "__main__":
    main()
