"""How fine a skin the contact needs: the anny left arm at 0, 1 and 2 subdivisions.

For each surface: its vertex count and spacing; how many vertices a fingertip (a sphere of 8 mm
radius pressed 2 mm deep) and a disk of 2 cm radius touch at five places; what a whole-hand grasp
and a pinch touch; and the FEM on a disk of 2 cm radius at 0.3 N (7.5 mm tissue, reference
resolution, 3 continuation levels): its deepest displacement and its time.

    python benchmarks/resolution.py [--levels 0 1 2] [--no-fem]
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from stmpl.table import markdown

SPOTS = [(0.3, 0.4), (0.45, 0.5), (0.6, 0.55), (0.5, 0.35), (0.4, 0.65)]


def count(fn) -> str:
    """The number of vertices ``fn()`` touches, or 0 where it finds no contact."""
    try:
        return len(fn())
    except ValueError:
        return 0


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--levels", type=int, nargs="+", default=[0, 1, 2])
    ap.add_argument("--no-fem", action="store_true")
    args = ap.parse_args()
    import stmpl.contact.pressing as contact
    from stmpl import AnnyBody, loads, predictor, tissue
    from stmpl.contact import objects
    from stmpl.contact.hand import Hand, grasp
    from stmpl.scene import Scene

    arm = AnnyBody().part("left_arm")
    hand = Hand()
    tip = objects.sphere(0.008)
    from stmpl.machine import describe

    print(f"machine: {describe()}")
    rows = []
    for k in args.levels:
        part = arm.subdivided(k)
        e = part.edges
        spacing = np.linalg.norm(part.vertices[e[:, 0]] - part.vertices[e[:, 1]], axis=1).mean()

        def tip_at(uv, tol):
            return contact.contact(
                part,
                contact.Pressing(tip, objects.press(part, tip, uv=uv, depth=0.002), 0.1),
                tolerance=tol,
            ).vertices

        tips0 = [count(lambda: tip_at(uv, 0.0)) for uv in SPOTS]
        tips2 = [count(lambda: tip_at(uv, 0.002)) for uv in SPOTS]
        disks = [loads.disk(part, uv=uv, radius=0.02, total=0.3).count for uv in SPOTS]
        whole = count(
            lambda: (
                contact.contact(part, grasp(part, hand, 0.7, 0.0, "whole").pressing(0.4)).vertices
            )
        )
        pinch = count(
            lambda: (
                contact.contact(part, grasp(part, hand, 0.5, 0.5, "pinch").pressing(0.4)).vertices
            )
        )
        row = {
            "level": k,
            "vertices": part.n_vertices,
            "spacing_mm": 1e3 * spacing,
            "tip": tips0,
            "tip_tol": tips2,
            "disk": disks,
            "whole": whole,
            "pinch": pinch,
        }
        if not args.no_fem:
            scene = Scene.from_load(
                part,
                tissue.constant(part, 0.0075),
                loads.disk(part, uv=(0.45, 0.5), radius=0.02, total=0.3),
            )
            fem = predictor.create("fem", levels=3)
            t0 = time.perf_counter()
            d = fem.predict(scene)
            row.update(
                fem_mm=1e3 * d.magnitude.max(),
                fem_s=time.perf_counter() - t0,
                fem_nodes=d.info["mesh"]["nodes"],
            )
        rows.append(row)
        print(row, flush=True)
    columns = [
        "subdivisions",
        "vertices",
        "spacing mm",
        "fingertip touches (tol 0 / 2 mm)",
        "2 cm-radius disk touches",
        "whole grasp",
        "pinch",
        "FEM 0.3 N disk: deepest mm, s, shell nodes",
    ]
    cells = []
    for r in rows:
        fem = f"{r['fem_mm']:.3f}, {r['fem_s']:.1f}, {r['fem_nodes']}" if "fem_mm" in r else "-"
        cells.append(
            [
                r["level"],
                r["vertices"],
                f"{r['spacing_mm']:.1f}",
                f"{'/'.join(map(str, r['tip']))} ; {'/'.join(map(str, r['tip_tol']))}",
                "/".join(map(str, r["disk"])),
                r["whole"],
                r["pinch"],
                fem,
            ]
        )
    print()
    print(markdown(columns, cells, "rrrllrrl"))


if __name__ == "__main__":
    main()
