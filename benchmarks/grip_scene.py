"""What a scene of anny's hand gripping her arm costs before any model answers it: setting the
grip, reading it back once kept, the gap field a pose model reads, and the distance the FEM's
contact asks of the hand at every iteration.

    python benchmarks/grip_scene.py [--grip whole] [--along 0.55] [--repeat 5]

The main job's arm (anny's left arm subdivided once, 2109 vertices); her right hand in a
``--grip`` at ``--along`` (:func:`stmpl.contact.closing.closing_grip`), set once into an empty
``STMPL_CACHE_DIR`` (cold) and read back after (kept); the grip scene closed 3 mm
(:func:`stmpl.contact.posing.gripped`: the grip read back and the gap field), and with its way
field read (a model with ``motion`` reads it; the scene computes it then); the gap field
alone (:func:`stmpl.contact.posing.signed_distance`, the rest skin against the closed hand); and
the FEM's contact distance (:meth:`fem.shapes.Surface.distance`, the hand smoothed as the FEM
presses it) at the skin's vertices and edge midpoints (the nodes of a quadratic skin) with the
hand closed 4 and 10 mm. Medians of ``--repeat`` calls; run it alone: the times are wall-clock.
"""

from __future__ import annotations

import argparse
import os
import tempfile
import time
import warnings

import numpy as np


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--grip", default="whole", choices=("whole", "tripod", "pinch"))
    ap.add_argument("--along", type=float, default=0.55)
    ap.add_argument("--repeat", type=int, default=5)
    args = ap.parse_args()
    warnings.simplefilter("ignore")
    os.environ["STMPL_CACHE_DIR"] = tempfile.mkdtemp(prefix="stmpl-grip-")

    import trimesh
    from _timing import median_time

    from fem.objects import closing
    from stmpl import tissue
    from stmpl.body.spec import part_from_spec
    from stmpl.contact.closing import cached_closing_grip, closed
    from stmpl.contact.posing import gripped, signed_distance
    from stmpl.machine import describe
    from stmpl.table import header, row

    arm = part_from_spec({"model": "anny", "subdivisions": 1}, "left_arm")
    t = tissue.constant(arm, 0.0075)
    print(f"{args.grip} grip at {args.along:g} of anny's left arm ({arm.n_vertices} vertices)")
    print(describe())
    print(header(["stage", "s", "calls"], "lrr"))
    t0 = time.perf_counter()
    grip = cached_closing_grip(arm, {}, "R", args.along, 0.0, args.grip)
    print(
        row(
            [
                "set the grip (cold: anny and the skin distances)",
                f"{time.perf_counter() - t0:.2f}",
                "1",
            ]
        )
    )
    kept = median_time(
        lambda: cached_closing_grip(arm, {}, "R", args.along, 0.0, args.grip), args.repeat
    )
    print(row(["read the kept grip back", f"{kept:.3f}", str(args.repeat)]))
    scene = median_time(lambda: gripped(arm, t, 0.003, {}, args.along, 0.0, args.grip), args.repeat)
    print(
        row(["the grip scene closed 3 mm (kept grip, gap field)", f"{scene:.3f}", str(args.repeat)])
    )
    way = median_time(
        lambda: gripped(arm, t, 0.003, {}, args.along, 0.0, args.grip).pose.way, args.repeat
    )
    print(
        row(
            [
                "... and its way field read (a motion model's; computed when first read)",
                f"{way:.3f}",
                str(args.repeat),
            ]
        )
    )
    hand = closed(grip, 0.003)
    mesh = trimesh.Trimesh(hand.vertices, hand.faces, process=False)
    gap = median_time(lambda: signed_distance(mesh, arm.vertices), args.repeat)
    print(row(["its gap field alone (2109 rest skin vertices)", f"{gap:.3f}", str(args.repeat)]))
    f = arm.faces
    e = np.unique(
        np.sort(np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]]), axis=1), axis=0
    )
    nodes = np.concatenate([arm.vertices, arm.vertices[e].mean(1)])
    surface = closing(grip)  # the hand as the FEM presses it
    for depth in (0.004, 0.010):
        at = surface.pushed(depth, None)
        s = median_time(lambda at=at: at.distance(nodes), args.repeat)
        print(
            row(
                [
                    f"FEM contact distance, closed {1e3 * depth:g} mm ({len(nodes)} nodes)",
                    f"{s:.3f}",
                    str(args.repeat),
                ]
            )
        )


if __name__ == "__main__":
    main()
