"""Ready-made objects to press on a body, and where to put them.

Meshes (``trimesh.Trimesh``, m, watertight) in their own frame, pressing face down: the object
presses along its local ``-z``, and its lowest point is at ``z = 0`` or below. :func:`press` gives
the pose that sets such an object on a part's surface point with its lowest point a given depth
into the skin; :func:`strap` a ring closed around a limb.

>>> tip = sphere(0.008)                                   # a fingertip
>>> pose = press(arm, tip, uv=(0.5, 0.5), depth=0.002)    # 2 mm into the skin
>>> c = contact(arm, Pressing(tip, pose, total=0.3, name="fingertip"))
"""

from __future__ import annotations

import numpy as np

from stmpl.contact.pressing import Pressing, rotation_matrix
from stmpl.loads import glyph_contours, place
from stmpl.part import BodyPart


def _length(name: str, value) -> float:
    v = float(value)
    if not np.isfinite(v) or v <= 0:
        raise ValueError(f"{name} must be a finite length > 0 m, got {value!r}")
    return v


def sphere(radius: float = 0.008, subdivisions: int = 3):
    """A sphere of ``radius`` (m) resting on ``z = 0`` (a fingertip is about 8 mm)."""
    import trimesh  # deferred: object meshes and closest points only

    m = trimesh.creation.icosphere(subdivisions, _length("radius", radius))
    return m.apply_translation([0, 0, radius])


def disk(
    radius: float = 0.01,
    rounding: float = 0.001,
    height: float = 0.01,
    sections: int = 64,
    arc: int = 8,
):
    """A flat-ended cylinder of ``radius`` and ``height`` (m) standing on its face at ``z = 0``,
    the face's rim rounded to ``rounding`` (m; 0: sharp), as the presses of the datasets are
    (:class:`fem.shapes.Punch`): a quarter circle of ``arc`` segments, ``sections`` round.
    """
    import trimesh  # deferred: object meshes and closest points only

    r, h = _length("radius", radius), _length("height", height)
    rho = float(rounding)
    if not (np.isfinite(rho) and 0 <= rho < min(r, h)):
        raise ValueError(f"rounding must be >= 0 and below the radius and height, got {rounding!r}")
    t = np.linspace(0.0, np.pi / 2, arc + 1)
    rim = np.stack([r - rho + rho * np.sin(t), rho - rho * np.cos(t)], 1)
    profile = np.vstack([[0.0, 0.0], rim if rho > 0 else [[r, 0.0]], [r, h], [0.0, h]])
    m = trimesh.creation.revolve(profile, sections=int(sections))
    m.merge_vertices()
    return m


def rod(radius: float = 0.005, length: float = 0.1, sections: int = 32):
    """A cylinder of ``radius`` and ``length`` (m) lying along the local ``x`` axis on ``z = 0``:
    it presses with its side, a line contact (a tool's edge, a bar).
    """
    import trimesh  # deferred: object meshes and closest points only

    m = trimesh.creation.cylinder(
        _length("radius", radius), _length("length", length), sections=sections
    )
    turn = np.eye(4)
    turn[:3, :3] = rotation_matrix([0.0, 1.0, 0.0], np.pi / 2)  # its axis from z to x
    m.apply_transform(turn)
    return m.apply_translation([0, 0, radius])


def letters(text: str = "ECCV", height: float = 0.03, depth: float = 0.008):
    """Block letters ``height`` (m) tall extruded ``depth`` (m), the text along local ``x``,
    pressing with their faces (``z = 0``) as the paper's teaser presses "ECCV" into an arm.
    """
    import shapely.geometry as geo  # deferred: block letters only
    import trimesh  # deferred: object meshes and closest points only

    if not isinstance(text, str) or not text.strip():
        raise ValueError(f"letters need some visible text, got {text!r}")
    h, d = _length("height", height), _length("depth", depth)
    shape = None  # even-odd fill: a contour inside another is a hole
    for c in glyph_contours(text):
        poly = geo.Polygon(c * h).buffer(0)
        shape = poly if shape is None else shape.symmetric_difference(poly)
    polys = list(shape.geoms) if hasattr(shape, "geoms") else [shape]
    parts = [trimesh.creation.extrude_polygon(p, d) for p in polys if p.area > 0]
    m = trimesh.util.concatenate(parts)
    m.merge_vertices()
    return m


def strap_ring(
    inner_radius: float, width: float = 0.03, thickness: float = 0.004, sections: int = 64
):
    """A flat ring (a strap closed on itself): ``inner_radius``, ``width`` along its axis (local
    ``z``, centred on 0) and ``thickness``, m.
    """
    import trimesh  # deferred: object meshes and closest points only

    r = _length("inner_radius", inner_radius)
    return trimesh.creation.annulus(
        r, r + _length("thickness", thickness), _length("width", width), sections=sections
    )


def surface_frame(part: BodyPart, at=None, *, uv=None, spin: float = 0.0) -> np.ndarray:
    """``(4, 4)`` frame at a surface point: origin on the skin, ``z`` the outward normal, ``x``
    along the limb (or the chart's ``u``) turned by ``spin`` rad about the normal.
    """
    sp = place(part, at, uv=uv)
    normal = sp.bary @ part.normals[part.faces[sp.face]]
    normal /= np.linalg.norm(normal)
    if part.axis is not None:
        ref = part.axis[-1] - part.axis[0]
    else:
        ref = np.array([1.0, 0.0, 0.0])
    ref = ref - normal * (ref @ normal)
    if np.linalg.norm(ref) < 1e-9:
        ref = np.cross(normal, [0.0, 0.0, 1.0])
    x = ref / np.linalg.norm(ref)
    x = np.cos(spin) * x + np.sin(spin) * np.cross(normal, x)
    out = np.eye(4)
    out[:3, 0], out[:3, 1], out[:3, 2], out[:3, 3] = x, np.cross(normal, x), normal, sp.position
    return out


def press(
    part: BodyPart, mesh, at=None, *, uv=None, depth: float = 0.002, spin: float = 0.0
) -> np.ndarray:
    """The pose that sets ``mesh`` (pressing along its local ``-z``) on the part's surface at
    ``at`` / ``uv`` with its lowest point ``depth`` m into the skin (along the normal there).
    """
    if not np.isfinite(depth):
        raise ValueError(f"depth must be finite, got {depth!r}")
    zmin, zmax = float(mesh.vertices[:, 2].min()), float(mesh.vertices[:, 2].max())
    if depth >= zmax - zmin:
        raise ValueError(
            f"depth {depth * 1e3:g} mm would sink the whole object into the skin (it is "
            f"{(zmax - zmin) * 1e3:.3g} mm tall along the press); press less deep"
        )
    frame = surface_frame(part, at, uv=uv, spin=spin)
    frame[:3, 3] -= (depth + zmin) * frame[:3, 2]
    return frame


def strap(
    part: BodyPart,
    at: float = 0.5,
    width: float = 0.03,
    squeeze: float = 0.003,
    thickness: float = 0.01,
    total: float = 0.5,
    name: str = "strap",
) -> Pressing:
    """A strap closed around a limb at fraction ``at`` along its axis, ``squeeze`` m tighter
    than the limb's median radius there: a :class:`~stmpl.contact.pressing.Pressing` ready for
    :func:`~stmpl.contact.pressing.contact`. (Penetration is measured to the nearest surface of the
    object, so the strap is thicker than it squeezes: ``thickness`` > 2 ``squeeze``.)
    """
    if part.axis is None:
        raise ValueError(f"part {part.name!r} has no limb axis: a strap goes around a limb")
    centre, direction, s0 = part.limb_frame(at)
    ring = np.abs(part.axial - s0) <= max(width, 0.01) / 2
    off = part.vertices[ring] - centre
    radius = float(np.median(np.linalg.norm(off - np.outer(off @ direction, direction), axis=1)))
    if not 0 < 2 * squeeze < thickness:
        raise ValueError(
            f"squeeze must be > 0 and under half the thickness "
            f"({thickness * 1e3:g} mm), got {squeeze * 1e3:g} mm"
        )
    if radius - squeeze <= 0:
        raise ValueError(
            f"squeeze {squeeze * 1e3:g} mm is more than the limb's radius "
            f"{radius * 1e3:.1f} mm there"
        )
    pose = np.eye(4)
    z = direction
    x = np.cross(z, [1.0, 0.0, 0.0] if abs(z[0]) < 0.9 else [0.0, 1.0, 0.0])
    x /= np.linalg.norm(x)
    pose[:3, 0], pose[:3, 1], pose[:3, 2], pose[:3, 3] = x, np.cross(z, x), z, centre
    return Pressing(strap_ring(radius - squeeze, width, thickness), pose, total, name)
