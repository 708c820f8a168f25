"""The body's mirror: a part of one side seen as its twin on the other (anny's right arm is its
left arm in the mirror, vertex for vertex, on every body), so that a model of one side serves
the other.
"""

from __future__ import annotations

import dataclasses

import numpy as np
from scipy.spatial import cKDTree

from stmpl.part import BodyPart
from stmpl.pose import Pose, Rigid
from stmpl.scene import Scene

MIRROR = np.array([-1.0, 1.0, 1.0])
"""The body's mirror: x (the body's left-right axis, for anny and SMPL alike) negated."""

_TWINS: dict = {}


def counterpart(name: str) -> str | None:
    """The other side's part of part ``name`` (``right_arm`` for ``left_arm``), or None."""
    for a, b in (("left_", "right_"), ("right_", "left_")):
        if name.startswith(a):
            return b + name[len(a) :]
    return None


def mirror_twin(part: BodyPart, template: BodyPart) -> BodyPart | None:
    """``part`` seen in the mirror as ``template``'s side: when ``part`` is the other side's
    limb (``right_arm`` for a ``left_arm`` template) of a mesh that is its mirror twin (the
    same vertex count, vertex ``i`` the mirror image of the template's vertex ``i`` across the
    body's x = 0 plane on the same body, and the same triangles up to order and winding: anny's
    arms are), the template's mesh with ``part``'s vertices mirrored (its normals mirrored too);
    else None. Which body it is does not matter: the correspondence is the mesh's.
    """
    if counterpart(part.name) != template.name or part.n_vertices != template.n_vertices:
        return None
    key = (part.faces.tobytes(), template.faces.tobytes())
    if key not in _TWINS:
        a = {tuple(sorted(f)) for f in part.faces.tolist()}
        _TWINS[key] = a == {tuple(sorted(f)) for f in template.faces.tolist()}
    if not _TWINS[key]:
        return None
    src = dict(part.source or {})
    src["mirrored_from"] = part.name
    return dataclasses.replace(
        template, vertices=part.vertices * MIRROR, normals=part.normals * MIRROR, source=src
    )


def self_mirror(part: BodyPart, tolerance: float = 1e-6) -> np.ndarray | None:
    """``(N,)`` int: the vertex each vertex of ``part`` becomes in the mirror, when the part is
    its own mirror image (anny's belly: every vertex's mirror image is a vertex within
    ``tolerance`` m, one each, and the triangles map onto triangles); else None. A press
    mirrored so is a press on the same part, and its answer the mirrored answer.
    """
    x = np.asarray(part.vertices, dtype=float)
    d, twin = cKDTree(x).query(x * MIRROR)
    if d.max() > tolerance or len(np.unique(twin)) != len(x):
        return None
    faces = {tuple(sorted(f)) for f in part.faces.tolist()}
    if faces != {tuple(sorted(f)) for f in twin[part.faces].tolist()}:
        return None
    return twin


def mirrored_scene(scene: Scene, twin) -> Scene:
    """``scene`` on its mirror twin ``twin``: the thickness and the force (or the pose's gap)
    vertex for vertex, a pose's objects, direction and way mirrored.
    """
    if scene.pose is None:
        return Scene(twin, scene.thickness, scene.force, meta=scene.meta)
    pose = scene.pose
    objects = tuple(
        Rigid(
            o.name,
            o.vertices * MIRROR,
            o.faces[:, ::-1],
            None if o.path is None else o.path * MIRROR,
        )
        for o in pose.objects
    )
    direction = None if pose.closing else pose.direction * MIRROR
    way = None if pose.way is None else pose.way * MIRROR
    mirrored = Pose(pose.gap, direction, objects, way)
    return Scene.posed(twin, scene.thickness, mirrored, **scene.meta)
