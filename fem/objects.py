"""The contact wing's objects as the FEM's rigid shapes: a posed mesh
(:class:`~stmpl.contact.pressing.Pressing`: a disk, a box, a user's file, a posed hand), a
scene's pose (:func:`at_pose`), anny's hand closing in a grip (:func:`closing`) and a dataset's
pressed objects (:func:`placed`).
"""

from __future__ import annotations

import numpy as np

from fem.shapes import (
    PRESSES,
    ROUNDING,
    Punch,
    Sphere,
    Surface,
    clearance,
    skin_near,
    skin_points,
    touching,
    unit,
)
from stmpl.contact.closing import closing_grip
from stmpl.contact.hand import Hand
from stmpl.contact.pressing import Pressing
from stmpl.part import BodyPart
from stmpl.pose import GAP_REACH, Pose, Rigid


def surface(pressing: Pressing, rounding: float = ROUNDING) -> Surface:
    """The object of ``pressing`` in body coordinates, as a rigid :class:`Surface`."""
    m = pressing.posed()
    return Surface(np.asarray(m.vertices), np.asarray(m.faces), rounding, name=pressing.name)


def at_pose(part: BodyPart, pose: Pose, rounding: float = ROUNDING) -> tuple[Surface, float]:
    """``(shape, depth)``: a scene's posed objects as one rigid :class:`Surface` (rounded by
    ``rounding``, m) moved back along the pose's direction (a closing pose's objects: back
    along their paths, the surface closing along them) to first contact with the skin, and
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
    path = np.concatenate([o.path for o in pose.objects]) if pose.closing else None
    shape = Surface(np.concatenate(vertices), np.concatenate(faces), rounding, path, name)
    d = None if pose.closing else unit(pose.direction)
    if pose.gap.min() >= GAP_REACH:  # every vertex far from the objects
        return shape, 0.0
    if pose.closing:  # a grip's fingers touch round the limb: the skin within 1 cm of them
        skin = skin_points(part, np.flatnonzero((pose.gap[part.faces] < 0.01).any(axis=1)))
    else:
        near = pose.near()
        centre = part.vertices[near].mean(0)
        reach = float(np.linalg.norm(part.vertices[near] - centre, axis=1).max()) + 0.01
        skin = skin_near(part, centre, reach)
    back = clearance(shape, d, skin)
    moved = shape.pushed(-back, None) if d is None else shape.moved(-back * d)
    return moved, max(back - rounding, 0.0)


def closing(grip: Rigid, rounding: float = ROUNDING) -> Surface:
    """A closing grip of anny's hand (:func:`stmpl.contact.closing.closing_grip`) as a rigid
    :class:`Surface` with its path: at depth 0 clear of the skin (its nearest point touching),
    at depth ``d`` (m) closed ``d`` further; its faces offset outward by ``rounding`` (m).
    """
    return Surface(grip.vertices, grip.faces, rounding, path=grip.path, name=grip.name)


def placed(part: BodyPart, kind: str, params: dict, hand: Hand | None = None):
    """``(shape, direction (3,))``: the rigid object of a press placement (``kind`` one of
    :data:`PRESSES`, ``params`` its ``at``, ``radius`` and for a disk ``rounding``) over vertex
    ``at`` of ``part``, facing along the inward normal there, moved back to first contact with
    the skin around it (:func:`fem.shapes.touching`): depth 0 touches, depth ``d`` presses
    ``d`` (m) in. A ``press_grip`` (``params`` its ``grip``, ``along`` and ``around``): anny's
    ``hand`` (default her right hand) closing from first touch, direction ``None``.
    """
    if kind == "press_grip":
        hand = hand if hand is not None else Hand(side="R")
        g = closing_grip(part, hand, params["along"], params["around"], params["grip"])
        shape = closing(g)
        return shape, None
    at, radius = int(params["at"]), float(params["radius"])
    p, n = part.vertices[at], part.normals[at]
    if kind == "press_disk":
        shape = Punch(p, -n, radius, rounding=float(params.get("rounding", 0.0)))
    elif kind == "press_sphere":
        shape = Sphere(p + radius * n, radius)
    else:
        raise ValueError(f"unknown press {kind!r}; use {list(PRESSES)}")
    return touching(shape, -n, skin_near(part, p, 3 * radius)), -n
