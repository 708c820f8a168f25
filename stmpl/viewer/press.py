"""From what a person chose in the viewer (an object, the skin vertex it is on, a force) to a
:class:`~stmpl.scene.Scene` and the object's mesh to draw.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

import stmpl.contact.pressing as contact
from stmpl import loads
from stmpl.contact import objects
from stmpl.contact.hand import GRIPS, cached_grasp, front_across
from stmpl.part import BodyPart
from stmpl.scene import Scene

OBJECTS = {
    "disk": "a flat disk (the paper's load)",
    "fingertip": "a fingertip (a sphere)",
    "hand": "anny's right hand in a grip",
    "strap": "a strap around the limb",
    "mesh": "your own mesh (upload it)",
}
"""The objects a person can press, and how the page names them."""

DEPTH = 0.002
"""How far (m) a pressed object's lowest point is set into the skin to find what it touches."""


@dataclass(frozen=True)
class Choice:
    """What the page asks: ``kind`` (a key of :data:`OBJECTS`) at skin ``vertex``, pressed with
    ``force`` N; ``radius_mm`` of a disk or fingertip; ``grip`` of the hand; ``spin`` rad about
    the skin's normal; ``mesh`` an uploaded ``trimesh.Trimesh`` (m) for ``mesh``.
    """

    kind: str = "disk"
    vertex: int = 0
    force: float = 0.3
    radius_mm: float = 20.0
    grip: str = "whole"
    spin: float = 0.0
    mesh: object = None

    def __post_init__(self) -> None:
        if self.kind not in OBJECTS:
            raise ValueError(f"object must be one of {sorted(OBJECTS)}, got {self.kind!r}")
        if not (np.isfinite(self.force) and self.force > 0):
            raise ValueError(f"force must be above 0 N, got {self.force!r}")
        if not (np.isfinite(self.radius_mm) and self.radius_mm > 0):
            raise ValueError(f"radius must be above 0 mm, got {self.radius_mm!r}")
        if self.grip not in GRIPS:
            raise ValueError(f"grip must be one of {sorted(GRIPS)}, got {self.grip!r}")
        if self.kind == "mesh" and self.mesh is None:
            raise ValueError("upload a mesh file (STL, OBJ, PLY, GLB) to press your own object")


def along_around(part: BodyPart, vertex: int) -> tuple[float, float]:
    """Where skin ``vertex`` lies on a limb: the fraction along its axis and the angle (rad)
    around it from the body's front (the inverse of :func:`stmpl.contact.hand.limb_point`).
    """
    s = part.axial
    along = float((s[vertex] - s.min()) / (s.max() - s.min()))
    centre, z, _ = part.limb_frame(along)
    ref = front_across(z)
    d = part.vertices[vertex] - centre
    return along, float(np.arctan2(np.cross(ref, d) @ z, ref @ d))


def patch(part: BodyPart, vertices: np.ndarray, lift: float = 0.0015):
    """The skin a load covers, drawn as its own surface ``lift`` m above the skin: the faces whose
    corners are all loaded (the paper's load is a force shared over skin, not a rigid object).
    """
    import trimesh  # deferred: object meshes only

    loaded = np.zeros(part.n_vertices, bool)
    loaded[vertices] = True
    faces = part.faces[loaded[part.faces].all(axis=1)]
    return trimesh.Trimesh(part.vertices + lift * part.normals, faces, process=False)


def pressed(part: BodyPart, thickness: np.ndarray, choice: Choice, phenotype: dict | None = None):
    """``(scene, object meshes posed in body coordinates)`` of ``choice`` on ``part``."""
    if not 0 <= choice.vertex < part.n_vertices:
        raise ValueError(
            f"vertex {choice.vertex} is not on the {part.name} (0..{part.n_vertices - 1})"
        )
    v, mm = int(choice.vertex), 1e-3
    if choice.kind == "disk":
        load = loads.disk(part, v, choice.radius_mm * mm, choice.force)
        return Scene.from_load(part, thickness, load), [patch(part, load.vertices)]
    if choice.kind in ("hand", "strap") and part.axis is None:
        raise ValueError(
            f"the {part.name} has no limb to {'grasp' if choice.kind == 'hand' else 'strap'}"
        )
    if choice.kind == "hand":
        along, around = along_around(part, v)
        grasp = cached_grasp(part, phenotype, along, around, choice.grip, DEPTH)
        press = grasp.pressing(choice.force, f"right hand ({choice.grip})")
    elif choice.kind == "strap":
        press = objects.strap(part, along_around(part, v)[0], total=choice.force)
    else:
        mesh = objects.sphere(choice.radius_mm * mm) if choice.kind == "fingertip" else choice.mesh
        pose = objects.press(part, mesh, v, depth=DEPTH, spin=choice.spin)
        press = contact.Pressing(mesh, pose, choice.force, choice.kind)
    touch = contact.contact(part, [press])
    return Scene.from_load(part, thickness, touch.load()), [press.posed()]
