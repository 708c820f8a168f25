"""A 10 N disk on the layered forearm, solved on the whole arm and on the patch it moves: the
time of each, and how far the two answers lie apart.

    python benchmarks/press_local.py [--force 10] [--tissue forearm] [--res reference]
        [--radius-mm 10] [--repeats 2] [--ramp 10]

The disk (a rigid flat punch) starts touching the skin (at first contact,
``fem.shapes.touching``) at chart point (0.35, 0.5) of anny's left arm and is pushed along the
inward normal until it carries the force (within 1 %), from rest each time. Run it alone: the
times are wall-clock, each the best of ``--repeats``.

``--ramp K``: instead, the force met in K equal steps on the whole arm, each from the last
answer, as a dataset's force levels are made: the time of each sample of the ramp.

``--strain``: instead, the whole arm's answer alone, and how far from the disk its strain
reaches: the elements whose small strain ``|sym(F) - I|`` (Frobenius, largest over the
element's points), or the part of the Green strain ``E`` that small strain leaves out
(``|E - (sym(F) - I)|``), passes each level, and how many nodes a cut at each distance holds
inside and on it (what a linear far field condensed onto the cut would cost).
"""

from __future__ import annotations

import argparse
import time
import warnings

import numpy as np

from fem.force_control import press_to_force
from fem.layers import preset
from fem.local import press_local
from fem.shapes import Punch, skin_near, touching
from fem.simulate import resolution, tissue_mesh
from fem.solver import Solver
from stmpl import AnnyBody, loads, tissue
from stmpl.machine import describe
from stmpl.table import header, row


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--force", type=float, default=10.0, help="N")
    ap.add_argument("--tissue", default="forearm")
    ap.add_argument("--res", default="reference")
    ap.add_argument("--radius-mm", type=float, default=10.0)
    ap.add_argument("--repeats", type=int, default=2)
    ap.add_argument("--ramp", type=int, default=0, help="K steps to the force, each from the last")
    ap.add_argument("--strain", action="store_true", help="how far the answer's strain reaches")
    args = ap.parse_args()
    warnings.simplefilter("ignore")
    part = AnnyBody(phenotype={"weight": 0.5}).part("left_arm")
    thickness = tissue.from_weight(part, 0.5)
    r = 1e-3 * args.radius_mm
    disk = loads.disk(part, uv=(0.35, 0.5), radius=r, total=1.0)
    centre = part.vertices[disk.vertices].mean(0)
    at = disk.vertices[np.argmin(np.linalg.norm(part.vertices[disk.vertices] - centre, axis=1))]
    p, n = part.vertices[at], part.normals[at]
    shape = touching(Punch(p, -n, r), -n, skin_near(part, p, 3 * r))  # at first contact
    print(
        f"{args.force:g} N, {args.radius_mm:g} mm disk on the {args.tissue} preset of anny's left "
        f"arm ({part.n_vertices} vertices), {args.res} resolution; {describe()}"
    )

    if args.ramp:
        ramp(part, thickness, shape, p, n, args)
        return
    if args.strain:
        reach(part, thickness, shape, p, n, args)
        return

    def whole():
        solver = whole_arm(part, thickness, p, args)
        return press_to_force(solver, shape, -n, args.force), len(solver.free)

    def local():
        answer, result = press_local(part, thickness, shape, -n, args.force, args.res, args.tissue)
        return answer, result

    times = {"whole": [], "local": []}
    for _ in range(args.repeats):
        t0 = time.perf_counter()
        full, dofs = whole()
        times["whole"].append(time.perf_counter() - t0)
        t0 = time.perf_counter()
        near, result = local()
        times["local"].append(time.perf_counter() - t0)
    if not (full.ok and near.ok):
        print(f"failed: whole {full.reason or 'ok'}; local {near.reason or 'ok'}")
        return
    peak = np.linalg.norm(full.displacement, axis=1).max()
    gap = np.linalg.norm(near.displacement - full.displacement, axis=1).max() / peak
    att = result.attempts[-1]
    print(header(["solve", "s (best)", "DOFs / patch", "depth mm", "reaction N", "note"], "lrrrrl"))
    print(
        row(
            [
                "whole arm",
                f"{min(times['whole']):.1f}",
                f"{dofs} DOFs",
                f"{1e3 * full.depth:.3f}",
                f"{full.reaction:.3f}",
                "",
            ]
        )
    )
    print(
        row(
            [
                "local",
                f"{min(times['local']):.1f}",
                f"{att['vertices']} of {part.n_vertices} vertices",
                f"{1e3 * near.depth:.3f}",
                f"{near.reaction:.3f}",
                f"{len(result.attempts)} attempt(s), margin {1e3 * att['margin_m']:.0f} mm, "
                f"ring moved {100 * att['ring_moved']:.2f} %",
            ]
        )
    )
    print(
        f"\nlocal vs whole: largest displacement gap {100 * gap:.2f} % of the deepest "
        f"({1e3 * peak:.2f} mm); {min(times['whole']) / min(times['local']):.1f}x faster"
    )


def whole_arm(part, thickness, p, args) -> Solver:
    """The whole arm's solver at ``args.res`` and ``args.tissue``, refined near ``p`` ``(3,)``."""
    mesh, material = tissue_mesh(part, thickness, args.res, args.tissue, near=p[None])
    return Solver(mesh, material, order=resolution(args.res).order)


def ramp(part, thickness, shape, p, n, args) -> None:
    """The force in ``args.ramp`` equal steps, each from the last answer, on the whole arm."""
    t0 = time.perf_counter()
    solver = whole_arm(part, thickness, p, args)
    print(f"mesh and solver: {time.perf_counter() - t0:.1f} s, {len(solver.free)} DOFs\n")
    print(header(["force N", "depth mm", "reaction N", "s", "note"], "rrrrl"))
    last, total = None, 0.0
    for force in np.linspace(args.force / args.ramp, args.force, args.ramp):
        t0 = time.perf_counter()
        answer = press_to_force(solver, shape, -n, float(force), start=last)
        dt = time.perf_counter() - t0
        total += dt
        if not answer.ok:
            print(row([f"{force:g}", "", "", f"{dt:.1f}", answer.reason]))
            return
        last = answer
        cells = [f"{force:g}", f"{1e3 * answer.depth:.3f}", f"{answer.reaction:.3f}", f"{dt:.1f}"]
        print(row([*cells, ""]), flush=True)
    print(f"\n{args.ramp} samples in {total:.0f} s: {total / args.ramp:.1f} s a sample")


def reach(part, thickness, shape, p, n, args) -> None:
    """How far from the disk's centre ``p`` the whole arm's answer is strained (``--strain``)."""
    solver = whole_arm(part, thickness, p, args)
    t0 = time.perf_counter()
    answer = press_to_force(solver, shape, -n, args.force)
    if not answer.ok:
        print(f"failed: {answer.reason}")
        return
    seconds = time.perf_counter() - t0
    print(
        f"{1e3 * answer.depth:.3f} mm, {answer.reaction:.3f} N in {seconds:.0f} s; "
        f"{len(solver.conn)} elements, {solver.n_all} nodes\n"
    )
    F = solver.deformation_gradient(answer.state)  # (T, Q, 3, 3)
    small = 0.5 * (F + F.swapaxes(-1, -2)) - np.eye(3)
    green = 0.5 * (F.swapaxes(-1, -2) @ F - np.eye(3))
    small_n = np.linalg.norm(small, axis=(-1, -2)).max(1)
    left_out = np.linalg.norm(green - small, axis=(-1, -2)).max(1)
    centres = solver.positions[solver.conn].mean(1)
    dist = 1e3 * np.linalg.norm(centres - p, axis=1)  # mm
    if hasattr(solver.material, "layer"):  # a layered tissue: each element's layer
        layer, names = solver.material.layer, [x.name for x in preset(args.tissue).layers]
    else:
        layer, names = np.zeros(len(dist), int), ["gel"]

    def by_layer(sel):
        counts = np.bincount(layer[sel], minlength=len(names))
        return {names[k]: int(c) for k, c in enumerate(counts) if c}

    print(
        header(
            [
                "level",
                "small strain above: elements",
                "farthest mm",
                "left out above: elements",
                "farthest mm",
                "beyond 60 mm, by layer",
            ],
            "lrrrrl",
        )
    )
    for level in (0.1, 0.03, 0.01, 0.003, 0.001):
        a, b = small_n > level, left_out > level
        cells = [
            f"{level:g}",
            a.sum(),
            f"{dist[a].max(initial=0):.0f}",
            b.sum(),
            f"{dist[b].max(initial=0):.0f}",
            ", ".join(f"{k}: {m}" for k, m in by_layer(a & (dist > 60)).items()),
        ]
        print(row([str(c) for c in cells]))
    print()
    print(
        header(
            [
                "cut at mm",
                "nodes inside",
                "nodes on the cut",
                "small strain outside",
                "left out outside",
            ],
            "rrrrr",
        )
    )
    for cut in (20, 40, 60, 80, 100):
        inside = dist < cut
        nodes_in = np.unique(solver.conn[inside])
        on_cut = np.intersect1d(nodes_in, solver.conn[~inside])
        cells = [
            cut,
            len(nodes_in),
            len(on_cut),
            f"{small_n[~inside].max():.4f}",
            f"{left_out[~inside].max():.4f}",
        ]
        print(row([str(c) for c in cells]))


if __name__ == "__main__":
    main()
