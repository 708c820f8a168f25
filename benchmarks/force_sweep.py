"""Real forces on real tissue: disks and fingertips pressed to 1-10 N, and anny's hand gripping
to 20 N, on the layered arm and belly; how many solves succeed, and why the others fail.

    python benchmarks/force_sweep.py [--out runs/force_sweep.jsonl] [--res medium]
        [--parts arm belly] [--objects disk fingertip grip] [--only CASE ...]
        [--friction MU] [--report] [--redo CASE ...]

Each case (part, object, placement) is one mesh and one solver; a disk or a fingertip is set
on the skin at first contact (``fem.shapes.touching``: where the skin is hollow, a flat disk set
on its middle vertex would start pressed into the skin around it); its forces are met one after
the other by force control (``fem.force_control.press_to_force``, within 1 %), each from the last
one's state; ``--friction MU``: with Coulomb's friction between object and skin
(``fem.friction``; frictionless by default). Every answer is a line of ``--out``; a case
already there is not solved again (the run resumes where it stopped). ``--report`` prints the
success table and the force-depth curves' convexity from that file without solving. Run it
alone, or with ``OMP_NUM_THREADS=1`` beside other work: the times are wall-clock.
"""

from __future__ import annotations

import argparse
import json
import time
import warnings
from pathlib import Path

import numpy as np

from fem.force_control import press_to_forces
from fem.objects import closing, placed
from fem.simulate import resolution, tissue_mesh
from fem.solver import Solver
from stmpl import AnnyBody, loads, tissue
from stmpl.contact.closing import closing_grip
from stmpl.contact.hand import Hand, SkinDistance
from stmpl.machine import describe
from stmpl.table import header, row

PARTS = {
    "arm": ("left_arm", "forearm", [(0.35, 0.5), (0.5, 0.4), (0.6, 0.6)]),
    "belly": ("belly", "abdomen", [(0.5, 0.5), (0.3, 0.5), (0.7, 0.4)]),
}
"""part name -> (anny part, tissue preset, chart points where the disk and the fingertip press)."""
GRIPS = [("whole", 0.3), ("tripod", 0.45), ("pinch", 0.6)]
"""(grip, fraction along the limb) of the arm's grips."""
FORCES = {
    "disk": [1.0, 2.0, 5.0, 10.0],
    "fingertip": [1.0, 2.0, 5.0, 10.0],
    "grip": [2.0, 5.0, 10.0, 20.0],
}
DISK_RADIUS, FINGERTIP_RADIUS = 0.01, 0.008
DISK_ROUNDING = 0.001
"""m: the disk's rim rounded as a real disk's edge is (a sharp rim concentrates the stress
without bound, and its answers at 10 N hinge on how finely the mesh resolves that corner)."""


def cases(parts, objects):
    """Every case as ``(key, part, object, where)``."""
    for name in parts:
        for obj in objects:
            if obj == "grip":
                if name == "arm":
                    for kind, along in GRIPS:
                        yield f"{name}/{kind} grip at {along}", name, obj, (kind, along)
                continue
            for uv in PARTS[name][2]:
                yield f"{name}/{obj} at {uv}", name, obj, uv


def solve_case(part_name, obj, where, res, body, friction: float = 0.0) -> list[dict]:
    """Every force of one case, as records."""
    anny_part, preset, _ = PARTS[part_name]
    part = body.part(anny_part)
    thickness = tissue.from_weight(part, body.phenotype["weight"])
    t0 = time.perf_counter()
    if obj == "grip":
        kind, along = where
        shape = closing(closing_grip(part, Hand(side="R"), along=along, kind=kind))
        direction = None
        closed = shape.pushed(0.005, None).vertices
        near = closed[SkinDistance(part)(closed) < 0]  # where the grip presses, 5 mm closed
    else:
        disk = loads.disk(part, uv=where, radius=DISK_RADIUS, total=1.0)
        centre = part.vertices[disk.vertices].mean(0)
        at = disk.vertices[np.argmin(np.linalg.norm(part.vertices[disk.vertices] - centre, axis=1))]
        kind = "press_disk" if obj == "disk" else "press_sphere"
        params = {"at": int(at), "radius": DISK_RADIUS, "rounding": DISK_ROUNDING}
        if obj == "fingertip":
            params = {"at": int(at), "radius": FINGERTIP_RADIUS}
        shape, direction = placed(part, kind, params)  # set on the skin at first contact
        near = part.vertices[at][None]
    mesh, material = tissue_mesh(part, thickness, res, preset, near=near)
    solver = Solver(mesh, material, order=resolution(res).order)
    setup = time.perf_counter() - t0
    out = []

    def record(force: float, answer) -> None:
        rec = dict(force=force, ok=answer.ok, reason=answer.reason, friction=friction)
        if not answer.reason.startswith("skipped"):
            rec["dofs"] = len(solver.free)
        if answer.ok:
            rec.update(
                depth_mm=1e3 * answer.depth,
                reaction=answer.reaction,
                area_cm2=1e4 * answer.area,
                peak_kpa=1e-3 * float(answer.pressure.max()),
                min_det_f=answer.min_det_F,
                compression=answer.compression,
                seconds=answer.time,
            )
        out.append(rec)
        if not answer.reason.startswith("skipped"):
            print(
                f"  {force:g} N: {'ok' if answer.ok else answer.reason} ({answer.time:.0f} s)",
                flush=True,
            )

    press_to_forces(solver, shape, direction, FORCES[obj], record, friction=friction)
    for rec in out:
        rec["setup_s"] = setup
    return out


def report(path: Path) -> None:
    records = [json.loads(line) for line in path.read_text().splitlines() if line.strip()]
    groups: dict = {}
    for r in records:
        groups.setdefault((r["part"], r["object"]), []).append(r)
    print(header(["part", "object", "forces N", "solved", "of", "share", "failures"], "llrrrrl"))
    solved = planned = 0
    for (part, obj), rs in groups.items():
        ok = sum(r["ok"] for r in rs)
        solved, planned = solved + ok, planned + len(rs)
        why = sorted({r["reason"] for r in rs if not r["ok"]})
        forces = ", ".join(f"{f:g}" for f in FORCES[obj])
        cells = [part, obj, forces, ok, len(rs), f"{100 * ok / len(rs):.0f} %", "; ".join(why)]
        print(row(cells))
    print(f"\nall: {solved} of {planned} solved ({100 * solved / max(planned, 1):.1f} %)")
    convex = total = 0
    for key in sorted({r["case"] for r in records}):
        rs = [r for r in records if r["case"] == key and r["ok"]]
        d = [0.0] + [r["depth_mm"] for r in rs]
        f = [0.0] + [r["reaction"] for r in rs]
        slopes = np.diff(f) / np.diff(d)
        if len(slopes) >= 2:
            total += 1
            convex += bool(np.all(np.diff(slopes) > 0))
    print(f"force-depth curves convex (slopes rising): {convex} of {total}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default="runs/force_sweep.jsonl")
    ap.add_argument("--res", default="medium")
    ap.add_argument("--parts", nargs="+", default=list(PARTS), choices=list(PARTS))
    ap.add_argument("--objects", nargs="+", default=list(FORCES), choices=list(FORCES))
    ap.add_argument("--weight", type=float, default=0.5, help="anny weight phenotype")
    ap.add_argument("--only", nargs="+", default=[], metavar="CASE", help="solve these cases only")
    ap.add_argument(
        "--friction", type=float, default=0.0, help="Coulomb's coefficient (0: frictionless)"
    )
    ap.add_argument("--report", action="store_true", help="only print the table of --out")
    ap.add_argument(
        "--redo",
        nargs="+",
        default=[],
        metavar="CASE",
        help="solve these cases again (their records in --out are replaced), e.g. "
        "'arm/pinch grip at 0.6'",
    )
    args = ap.parse_args()
    path = Path(args.out)
    if args.report:
        report(path)
        return
    warnings.simplefilter("ignore")
    path.parent.mkdir(parents=True, exist_ok=True)
    done = set()
    if path.exists():
        records = [json.loads(line) for line in path.read_text().splitlines() if line.strip()]
        unknown = set(args.redo) - {r["case"] for r in records}
        if unknown:
            raise SystemExit(f"--redo: no such case in {path}: {', '.join(sorted(unknown))}")
        kept = [r for r in records if r["case"] not in args.redo]
        if len(kept) < len(records):
            path.write_text("".join(json.dumps(r) + "\n" for r in kept))
        done = {r["case"] for r in kept}
    body = AnnyBody(phenotype={"weight": args.weight})
    print(f"force sweep, {args.res} resolution; {describe()}", flush=True)
    for key, part_name, obj, where in cases(args.parts, args.objects):
        if key in done or (args.only and key not in args.only):
            continue
        print(key, flush=True)
        try:
            records = solve_case(part_name, obj, where, args.res, body, args.friction)
        except ValueError as e:  # a case that cannot be set up is a failure with its reason
            records = [dict(force=f, ok=False, reason=f"set-up: {e}") for f in FORCES[obj]]
        with path.open("a") as fh:
            for rec in records:
                rec.update(case=key, part=part_name, object=obj)
                fh.write(json.dumps(rec) + "\n")
    report(path)


if __name__ == "__main__":
    main()
