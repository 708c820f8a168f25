"""Scenes given by where objects are (:class:`~stmpl.pose.Pose`): the objects' meshes at their
pose, and the gap field a learned model reads: each rest skin vertex's distance to them, inside
them along the way they press (:mod:`stmpl.contact.gap`; a closing grip: its signed distance).

>>> tip = objects.sphere(0.008)
>>> scene = posed(arm, thickness, tip, objects.press(arm, tip, uv=(0.5, 0.5), depth=0.002))
>>> answer = stmpl.predictor.create("fem", tissue="forearm").predict(scene)
>>> answer.reaction, answer.force          # N, and N on each vertex
>>> grip = gripped(arm, thickness, depth=0.003, kind="pinch")   # anny's hand closing on it
"""

from __future__ import annotations

from functools import partial

import numpy as np

from stmpl.contact import gap as along
from stmpl.contact import objects
from stmpl.contact.closing import cached_closing_grip, closed, closing_grip
from stmpl.contact.gap import way as way_field
from stmpl.contact.hand import Hand
from stmpl.contact.pressing import check_pose, distance_to_surface, winding_number
from stmpl.mesh import Mesh
from stmpl.part import BodyPart
from stmpl.pose import GAP_REACH, Pose, Rigid
from stmpl.scene import Scene


def signed_distance(
    mesh,
    points: np.ndarray,
    upto: float = GAP_REACH,
    before: np.ndarray | None = None,
    shift: float = 0.0,
) -> np.ndarray:
    """``(P,)`` each point's signed distance to a triangle mesh (m; negative inside it, inside
    where its generalized winding number exceeds 1/2), cut at ``upto`` outside.

    ``before`` ``(P,)``: the same field (cut at ``upto``) before the mesh's points moved at
    most ``shift`` (m) each. No point of the surface then sweeps farther than ``shift``, so a
    point farther than that from the surface before stays on its side of it: only the others'
    sides are measured again (the winding numbers, half the cost), with the same answer.
    """
    points = np.asarray(points, dtype=float).reshape(-1, 3)
    lo, hi = np.asarray(mesh.bounds)
    box = np.linalg.norm(np.maximum(0, np.maximum(lo - points, points - hi)), axis=1)
    out = np.full(len(points), float(upto))
    near = np.flatnonzero(box < upto)  # a point farther from the box is farther from the mesh
    side = None
    if before is not None:
        before = np.asarray(before, dtype=float)
        side = np.where(np.abs(before[near]) > shift, np.sign(before[near]), 0.0)
    if not len(near):
        return out
    d = distance_to_surface(mesh, points[near], upto=upto)  # exact up to upto
    if side is None:
        inside = winding_number(mesh, points[near]) > 0.5
    else:
        inside = side < 0
        unsure = np.flatnonzero(side == 0)
        if len(unsure):
            inside[unsure] = winding_number(mesh, points[near][unsure]) > 0.5
    deep = np.flatnonzero(inside & (d > upto))  # inside deeper than upto: exactly too
    if len(deep):
        d[deep] = distance_to_surface(mesh, points[near][deep])
    d = np.where(inside, -d, np.minimum(d, upto))
    out[near] = d
    return out


def posed(
    part: BodyPart,
    thickness,
    mesh,
    pose=None,
    direction=None,
    name: str = "object",
    **meta,
) -> Scene:
    """The scene of ``mesh`` (a ``trimesh.Trimesh`` in its own frame, m, pressing along its
    local ``-z`` as :mod:`stmpl.contact.objects` makes them) set by ``pose`` ``(4, 4)`` (default
    none) on ``part`` with tissue ``thickness`` ``(N,)`` (m). ``direction`` ``(3,)``: the way
    it presses, default its local ``-z`` in body coordinates. Several objects: a list of
    ``(mesh, pose, name)``, pressing along one ``direction``.
    """
    items = mesh if isinstance(mesh, list) else [(mesh, pose, name)]
    if not items:
        raise ValueError("a posed scene needs at least one object")
    if direction is None:
        first = np.eye(4) if items[0][1] is None else check_pose(items[0][1])
        direction = first[:3, :3] @ np.array([0.0, 0.0, -1.0])
    d = np.asarray(direction, dtype=float)
    if d.shape != (3,) or not np.isfinite(d).all() or not np.linalg.norm(d) > 0:
        raise ValueError(f"direction must be a finite nonzero 3-vector, got {direction!r}")
    d = d / np.linalg.norm(d)
    rigid, gap = [], np.full(part.n_vertices, GAP_REACH)
    for m, p, n in items:
        if not (hasattr(m, "vertices") and hasattr(m, "faces") and hasattr(m, "copy")):
            raise TypeError(
                f"object {n!r}: the mesh must be a trimesh.Trimesh or stmpl.mesh.Mesh, got "
                f"{type(m)}"
            )
        P = np.eye(4) if p is None else check_pose(p)
        at = m.copy().apply_transform(P)
        if len(at.faces) == 0 or not np.isfinite(at.vertices).all():
            raise ValueError(f"object {n!r}: the mesh has no faces or non-finite vertices")
        rigid.append(Rigid(n, np.asarray(at.vertices), np.asarray(at.faces)))
        gap = np.minimum(gap, _gap(part, at, d))
    pose = Pose(gap, d, tuple(rigid), partial(way_field, part.vertices, gap, d))
    return Scene.posed(part, thickness, pose, **meta)


def _gap(part: BodyPart, mesh, direction) -> np.ndarray:
    """``(N,)`` the gap field of one object ``mesh`` (at its pose) on ``part``'s rest skin:
    inside it along ``direction`` (the deeper), outside its signed distance (the nearer); a
    closing object's (``direction`` None) its signed distance.
    """
    near = signed_distance(mesh, part.vertices)
    if direction is None:
        return near
    return np.minimum(along.mesh(mesh, part.vertices, direction), near)


def moved(scene: Scene, distance: float) -> Scene:
    """``scene`` (given by a pose) with its objects moved ``distance`` (m; negative: back) along
    the pose's direction, or a closing pose's objects closed that much further along their
    paths; the gap field measured again.
    """
    pose = scene.pose
    if pose is None or not pose.objects:
        raise ValueError("only a scene given by objects at their pose can be moved")
    if not np.isfinite(distance):
        raise ValueError(f"the distance to move must be finite (m), got {distance!r}")
    rigid, gap = [], np.full(scene.part.n_vertices, GAP_REACH)
    for o in pose.objects:
        step = distance * (o.path if pose.closing else pose.direction)
        r = Rigid(o.name, o.vertices + step, o.faces, o.path)
        rigid.append(r)
        mesh = Mesh(r.vertices, r.faces)
        if pose.closing and len(pose.objects) == 1:  # the gap is this object's signed distance
            shift = float(np.linalg.norm(step, axis=-1).max())
            gap = signed_distance(mesh, scene.part.vertices, before=pose.gap, shift=shift)
        else:
            gap = np.minimum(gap, _gap(scene.part, mesh, pose.direction))
    way = partial(way_field, scene.part.vertices, gap, pose.direction, tuple(rigid))
    return Scene.posed(
        scene.part, scene.thickness, Pose(gap, pose.direction, tuple(rigid), way), **scene.meta
    )


def gripped(
    part: BodyPart,
    thickness,
    depth: float,
    hand: Hand | dict | None = None,
    along: float = 0.5,
    around: float = 0.0,
    kind: str = "whole",
    **meta,
) -> Scene:
    """The scene of anny's ``hand`` (default her right hand, its grip kept on disk:
    :func:`~stmpl.contact.closing.cached_closing_grip`) in a ``kind`` of grip round the
    limb ``part`` (``along``, ``around`` as for :func:`~stmpl.contact.hand.grasp`), closed
    ``depth`` (m) along its path from first touch (:func:`~stmpl.contact.closing.closing_grip`):
    a closing pose (its direction ``None``; its answer's reaction is the squeeze, the whole
    contact force). ``hand``: a :class:`~stmpl.contact.hand.Hand`, or the phenotype of the
    body whose right hand it is (a dict; its grip kept on disk too).
    """
    if not (np.isfinite(depth) and depth >= 0):
        raise ValueError(f"a grip's depth must be >= 0 m, got {depth!r}")
    if isinstance(hand, Hand):
        grip = closing_grip(part, hand, along, around, kind)
    else:
        grip = cached_closing_grip(part, hand, "R", along, around, kind)
    grip = closed(grip, depth)
    gap = _gap(part, Mesh(grip.vertices, grip.faces), None)
    way = partial(way_field, part.vertices, gap, None, (grip,))
    return Scene.posed(part, thickness, Pose(gap, None, (grip,), way), **meta)


def first_touch(part: BodyPart, thickness, kind: str, params: dict, hand: Hand | None = None):
    """The scene of a dataset's pressed object (``kind`` ``press_disk``, ``press_sphere`` or
    ``press_grip``; ``params`` as its samples record them) where the FEM started pressing it:
    a disk (:func:`~stmpl.contact.objects.disk`) or ball meshed and set at its recorded pose
    moved back by its recorded ``depth`` along its ``direction``; a grip, anny's ``hand``
    (default her right hand) at its first touch (closed 0 mm). What force control
    (:mod:`stmpl.contact.force_control`) starts from to meet a sample's force.
    """
    if kind == "press_grip":
        return gripped(
            part,
            thickness,
            0.0,
            hand,
            float(params["along"]),
            float(params["around"]),
            params["grip"],
        )
    try:
        centre, d = np.asarray(params["centre"], float), np.asarray(params["direction"], float)
        radius, depth = float(params["radius"]), float(params["depth"])
    except (KeyError, TypeError) as e:
        raise ValueError(f"a {kind} sample does not record its object's pose ({e})") from e
    if kind == "press_sphere":
        mesh = objects.sphere(radius, subdivisions=4)  # the ball's lowest point at the origin
    elif kind == "press_disk":
        mesh = objects.disk(radius, float(params.get("rounding", 0.0)))  # its face at z = 0
    else:
        raise ValueError(f"unknown pressed object {kind!r}: press_disk, press_sphere, press_grip")
    d = d / np.linalg.norm(d)
    pose = np.eye(4)  # the local -z along the press, the front (the face, the ball's lowest
    pose[:3, 2] = -d  # point) at its place at first touch
    a = np.cross(-d, [1.0, 0.0, 0.0] if abs(d[0]) < 0.9 else [0.0, 1.0, 0.0])
    pose[:3, 0] = a / np.linalg.norm(a)
    pose[:3, 1] = np.cross(pose[:3, 2], pose[:3, 0])
    front = centre + (radius * d if kind == "press_sphere" else 0.0)
    pose[:3, 3] = front - depth * d
    return posed(part, thickness, mesh, pose, name=kind.removeprefix("press_"))


def sample_way(part: BodyPart, kind: str, params: dict, gap) -> np.ndarray:
    """``(N, 3)`` the way field (:attr:`stmpl.pose.Pose.way`) of a dataset sample on ``part``
    with gap field ``gap`` ``(N,)`` (m, as a pose model reads it): a pressed disk's or ball's
    recorded ``direction``; a grip's, anny's right hand (its grip kept on disk:
    :func:`~stmpl.contact.closing.cached_closing_grip`) closed the recorded ``depth``.
    """
    if kind != "press_grip":
        try:
            return way_field(part.vertices, gap, params["direction"])
        except (KeyError, TypeError) as e:
            raise ValueError(f"a {kind} sample does not record its press direction ({e})") from e
    try:
        grip = cached_closing_grip(
            part, None, "R", float(params["along"]), float(params["around"]), params["grip"]
        )
        depth = float(params["depth"])
    except (KeyError, TypeError) as e:
        raise ValueError(f"a grip sample does not record its placement and depth ({e})") from e
    return way_field(part.vertices, gap, None, (closed(grip, depth),))
