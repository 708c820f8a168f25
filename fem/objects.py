"""The contact wing's objects as the FEM's rigid shapes: a posed mesh
(:class:`~stmpl.contact.pressing.Pressing`: a disk, a box, a user's file, a posed hand), a
scene's pose (:func:`at_pose`), anny's hand closing in a grip (:func:`grip`) and a dataset's
pressed objects (:func:`placed`).
"""

from __future__ import annotations

import numpy as np
from trimesh.remesh import subdivide_loop

from fem.shapes import (
    PRESSES,
    ROUNDING,
    Punch,
    Sphere,
    Surface,
    clearance,
    skin_near,
    touching,
    unit,
)
from stmpl.contact.hand import Hand, SkinDistance, grasp
from stmpl.contact.pressing import Pressing
from stmpl.part import BodyPart
from stmpl.pose import GAP_REACH, Pose

OPEN = 0.01
"""m: how far back along its path a grip may open to clear the skin."""


def surface(pressing: Pressing, rounding: float = ROUNDING) -> Surface:
    """The object of ``pressing`` in body coordinates, as a rigid :class:`Surface`."""
    m = pressing.posed()
    return Surface(np.asarray(m.vertices), np.asarray(m.faces), rounding, name=pressing.name)


def at_pose(part: BodyPart, pose: Pose, rounding: float = ROUNDING) -> tuple[Surface, float]:
    """``(shape, depth)``: a scene's posed objects as one rigid :class:`Surface` (rounded by
    ``rounding``, m) moved back along the pose's direction to first contact with the skin, and
    the depth (m) that presses it to the pose: where the objects' own faces lie (the rounded
    surface stands ``rounding`` outside them). Depth 0 when the objects do not reach the skin.
    """
    if not pose.objects:
        raise ValueError(
            "the FEM presses the objects themselves, and this pose gives only its gap field"
        )
    vertices, faces, start = [], [], 0
    for o in pose.objects:
        vertices.append(o.vertices)
        faces.append(o.faces + start)
        start += len(o.vertices)
    name = " + ".join(pose.names())
    shape = Surface(np.concatenate(vertices), np.concatenate(faces), rounding, name=name)
    d = unit(pose.direction)
    if pose.gap.min() >= GAP_REACH:  # every vertex far from the objects
        return shape, 0.0
    near = pose.near()
    centre = part.vertices[near].mean(0)
    reach = float(np.linalg.norm(part.vertices[near] - centre, axis=1).max()) + 0.01
    back = clearance(shape, d, skin_near(part, centre, reach))
    return shape.moved(-back * d), max(back - rounding, 0.0)


def grip(
    part: BodyPart,
    hand: Hand,
    along: float = 0.5,
    around: float = 0.0,
    kind: str = "whole",
    reach: float = 0.008,
    rounding: float = ROUNDING,
    subdivisions: int = 2,
) -> Surface:
    """Set anny's ``hand`` around the limb ``part`` (see :func:`stmpl.contact.hand.grasp`),
    closing in a ``kind`` of grip: a :class:`Surface` with a path, at depth 0 clear of the skin
    (its nearest point touching), at depth ``d`` (m) closed ``d`` further. The path is the
    straight line between the hand set 1 mm and ``reach`` (m, below 10 mm) deep, carried back
    until the hand clears the skin. A hand that cuts into the limb however far it opens (a
    finger the grasp could not stretch clear) is refused, with the finger's name and depth.
    anny's hand (edges of 1.5-11 mm) is smoothed by ``subdivisions`` of Loop's scheme first
    (each quarters its edges' length), so that the skin slides over rounded fingers.
    """
    if not (np.isfinite(reach) and 0.002 <= reach < 0.01):
        raise ValueError(f"reach must lie in [2, 10) mm, got {1e3 * reach:g} mm")
    first = 0.001
    near = grasp(part, hand, along, around, kind, depth=first)
    deep = grasp(part, hand, along, around, kind, depth=reach)
    # Loop's subdivision is linear in the vertices: the smoothed path is the path smoothed
    closer, faces = subdivide_loop(near.vertices, near.faces, iterations=subdivisions)
    path, _ = subdivide_loop(
        (deep.vertices - near.vertices) / (reach - first), near.faces, iterations=subdivisions
    )
    skin = SkinDistance(part)

    def clearance(back: float) -> np.ndarray:
        return skin(closer - back * path)

    lo, hi = 0.0, None
    for back in np.arange(0.0, OPEN + 1e-9, 0.0005):
        if clearance(back).min() >= 0:
            hi = back
            break
        lo = back
    if hi is None:
        d = clearance(OPEN)
        worst = int(np.argmin(d))
        j = int(np.argmin(np.linalg.norm(near.vertices - closer[worst], axis=1)))
        finger = next((f for f, ids in hand.finger_of.items() if j in ids), "palm")
        raise ValueError(
            f"the hand's {finger} lies {-1e3 * d[worst]:.1f} mm inside the skin however far the "
            f"{kind} grip opens (at {along:g} along, {around:g} around): choose another place "
            "or grip"
        )
    if hi > 0:
        for _ in range(20):
            mid = 0.5 * (lo + hi)
            lo, hi = (mid, hi) if clearance(mid).min() < 0 else (lo, mid)
    start = closer - hi * path
    return Surface(start, faces, rounding, path=path, name=f"hand ({kind} grip)")


def placed(part: BodyPart, kind: str, params: dict):
    """``(shape, direction (3,))``: the rigid object of a press placement (``kind`` one of
    :data:`PRESSES`, ``params`` its ``at``, ``radius`` and for a disk ``rounding``) over vertex
    ``at`` of ``part``, facing along the inward normal there, moved back to first contact with
    the skin around it (:func:`fem.shapes.touching`): depth 0 touches, depth ``d`` presses
    ``d`` (m) in.
    """
    at, radius = int(params["at"]), float(params["radius"])
    p, n = part.vertices[at], part.normals[at]
    if kind == "press_disk":
        shape = Punch(p, -n, radius, rounding=float(params.get("rounding", 0.0)))
    elif kind == "press_sphere":
        shape = Sphere(p + radius * n, radius)
    else:
        raise ValueError(f"unknown press {kind!r}; use {list(PRESSES)}")
    return touching(shape, -n, skin_near(part, p, 3 * radius)), -n
