"""External loads as per-vertex normal forces, the paper's way: the loaded vertices V each carry
``F_i = F_total / |V|`` along the inward vertex normal.

Primitives: :func:`disk`, :func:`ellipse`, :func:`seam_disk` (measured on the surface, so they cross
the UV seam unbroken), :func:`spots` (several small disks at once: fingertips, studs), :func:`band`
(a ring around a limb), :func:`letter` (a block-letter contour laid on the UV chart). Each returns a
:class:`Load` that reports its vertex count, contact area and mean pressure. Several loads add up
with :func:`combine`.

A load's place is a :class:`~stmpl.surface.SurfacePoint`, or anything :func:`place` turns into
one: a vertex index, a 3D point on the part (m), or chart coordinates ``uv=(u, v)``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from stmpl import surface
from stmpl.part import BodyPart

FORCE_RANGE = (0.0, 20.0)
"""Normalisation range of per-vertex force, N (the paper's [0, 20] N)."""


@dataclass(frozen=True, eq=False)
class Load:
    """Loaded vertices and the force they share.

    Attributes:
        kind: primitive name. params: its parameters (JSON-serialisable; lengths in m).
        vertices: ``(K,)`` loaded vertex indices. total: F_total, N.
        force: ``(N,)`` normal force magnitude per vertex, N (pushes along ``-normal``).
        area: contact area, m^2 (barycentric areas of the loaded vertices).
    """

    kind: str
    params: dict
    vertices: np.ndarray
    total: float
    force: np.ndarray
    area: float
    parts: tuple = field(default=())
    part_id: str = ""
    """The :attr:`~stmpl.part.BodyPart.fingerprint` of the part the load was built on (a
    scene refuses a load of another part)."""
    source: object = field(default=None, repr=False)
    """What made the load, when it is more than a shape (a
    :class:`~stmpl.contact.pressing.Contact`)."""

    @property
    def count(self) -> int:
        return int(len(self.vertices))

    @property
    def pressure(self) -> float:
        """Mean pressure F_total / area, Pa."""
        return self.total / self.area

    def summary(self) -> str:
        return (
            f"{self.kind}: {self.total:g} N on {self.count} vertices, "
            f"{self.area * 1e4:.2f} cm^2, mean pressure {self.pressure / 1e3:.2f} kPa"
        )

    def to_dict(self) -> dict:
        return {
            "kind": self.kind,
            "params": self.params,
            "total": self.total,
            "count": self.count,
            "area": self.area,
            "pressure": self.pressure,
        }


def place(part: BodyPart, at=None, *, uv=None, tolerance: float = 0.01) -> surface.SurfacePoint:
    """A surface point from a vertex index, a 3D point (m, within ``tolerance`` of the part) or
    chart coordinates ``uv``.
    """
    if isinstance(at, surface.SurfacePoint):
        return at
    if (at is None) == (uv is None):
        raise ValueError("give exactly one of a place (vertex index or 3D point) and uv=(u, v)")
    if uv is not None:
        return surface.point_at_uv(part, uv)
    if isinstance(at, (int, np.integer)):
        return surface.vertex_point(part, int(at))
    return surface.closest_point(part, at, tolerance)


def from_vertices(
    part: BodyPart,
    vertices,
    total: float,
    kind: str = "vertices",
    params: dict | None = None,
    whole: bool = True,
) -> Load:
    """Spread ``total`` (N) equally over the given vertices. ``whole=False`` (the primitives)
    refuses a load that covers every vertex of the part: a shape larger than the part.
    """
    total = _check_total(total)
    idx = np.unique(np.asarray(vertices, dtype=np.int64))
    if idx.size == 0:
        raise ValueError(
            f"{kind} load touches no vertex of part {part.name!r}: "
            f"make it larger or move it ({params})"
        )
    if idx.min() < 0 or idx.max() >= part.n_vertices:
        raise ValueError(f"{kind} load: vertex indices must be in [0, {part.n_vertices})")
    if not whole and idx.size == part.n_vertices:
        raise ValueError(
            f"{kind} load covers the whole part {part.name!r} (all "
            f"{part.n_vertices} vertices): it is larger than the part; make it "
            f"smaller ({params})"
        )
    force = np.zeros(part.n_vertices)
    force[idx] = total / idx.size
    _check_force(force)
    return Load(
        kind,
        dict(params or {}),
        idx,
        total,
        force,
        float(part.vertex_areas[idx].sum()),
        part_id=part.fingerprint,
    )


def disk(part: BodyPart, at=None, radius: float = 0.02, total: float = 1.0, *, uv=None) -> Load:
    """A circular disk of ``radius`` (m, geodesic) centred at a surface place."""
    _check_length("radius", radius)
    src = place(part, at, uv=uv)
    d = surface.geodesic_distance(part, src, local=max(0.05, 1.25 * radius))
    return from_vertices(
        part,
        np.nonzero(d <= radius)[0],
        total,
        "disk",
        {"centre": src.position.tolist(), "radius": float(radius)},
        whole=False,
    )


def ellipse(
    part: BodyPart,
    at=None,
    semi_axes=(0.03, 0.015),
    angle: float = 0.0,
    total: float = 1.0,
    *,
    uv=None,
) -> Load:
    """An elliptical disk with semi-axes ``(a, b)`` (m); ``a`` lies at ``angle`` (rad) from the
    chart's ``u`` direction in the tangent plane at the centre.
    """
    a, b = (float(x) for x in semi_axes)
    _check_length("semi-axis a", a)
    _check_length("semi-axis b", b)
    if not math.isfinite(angle):
        raise ValueError(f"ellipse angle must be finite, got {angle}")
    src = place(part, at, uv=uv)
    d = surface.geodesic_distance(part, src, local=max(0.05, 1.25 * max(a, b)))
    xy = surface.log_map(part, src, d)
    c, s = math.cos(angle), math.sin(angle)
    x, y = xy @ np.array([c, s]), xy @ np.array([-s, c])
    inside = (x / a) ** 2 + (y / b) ** 2 <= 1.0
    return from_vertices(
        part,
        np.nonzero(inside)[0],
        total,
        "ellipse",
        {"centre": src.position.tolist(), "semi_axes": [a, b], "angle": float(angle)},
        whole=False,
    )


def spots(
    part: BodyPart,
    at=None,
    count: int = 3,
    radius: float = 0.008,
    spread: float = 0.04,
    total: float = 1.0,
    *,
    uv=None,
) -> Load:
    """``count`` small disks of ``radius`` (m, geodesic) pressed at once, as fingertips or the
    studs of a tool do: the first centred at a surface place, the others on the vertices within
    geodesic ``spread`` (m) of it, spread evenly (each the farthest from the centres before it).
    ``F_total`` is split equally over every vertex they touch, as for a grasp.
    """
    if isinstance(count, bool) or not isinstance(count, (int, np.integer)) or count < 1:
        raise ValueError(f"spots count must be an integer >= 1, got {count!r}")
    _check_length("radius", radius)
    _check_length("spread", spread)
    src = place(part, at, uv=uv)
    local = max(0.05, 1.25 * (spread + radius))
    d = surface.geodesic_distance(part, src, local=local)
    near = np.flatnonzero(d <= spread)
    if count > 1 and near.size < count:
        raise ValueError(
            f"spots: only {near.size} vertices lie within spread {spread} m of the "
            f"centre, fewer than count={count}; widen the spread"
        )
    hit, centres, gap = [np.flatnonzero(d <= radius)], [src.position], d[near]
    for _ in range(count - 1):
        v = int(near[int(np.argmax(gap))])
        dv = surface.geodesic_distance(part, surface.vertex_point(part, v), local=local)
        hit.append(np.flatnonzero(dv <= radius))
        centres.append(part.vertices[v])
        gap = np.minimum(gap, dv[near])
    return from_vertices(
        part,
        np.concatenate(hit),
        total,
        "spots",
        {
            "centre": src.position.tolist(),
            "count": int(count),
            "radius": float(radius),
            "spread": float(spread),
            "centres": [np.asarray(c).tolist() for c in centres],
        },
        whole=False,
    )


def seam_vertices_ordered(part: BodyPart) -> np.ndarray:
    """Seam vertices ordered along the seam (by limb axis, else by principal direction)."""
    sv = part.seam_vertices
    if sv.size == 0:
        raise ValueError(f"part {part.name!r} has no UV seam")
    if part.axis is not None:
        key = part.axial[sv]
    else:
        x = part.vertices[sv] - part.vertices[sv].mean(0)
        key = x @ np.linalg.svd(x, full_matrices=False)[2][0]
    return sv[np.argsort(key)]


def seam_disk(part: BodyPart, at: float = 0.5, radius: float = 0.02, total: float = 1.0) -> Load:
    """A disk centred on the UV seam, at fraction ``at`` in [0, 1] along it."""
    if not 0.0 <= at <= 1.0:
        raise ValueError(f"seam_disk at must be in [0, 1] (fraction along the seam), got {at}")
    sv = seam_vertices_ordered(part)
    v = int(sv[int(round(at * (len(sv) - 1)))])
    load = disk(part, v, radius, total)
    return Load(
        "seam_disk",
        {**load.params, "at": float(at), "seam_vertex": v},
        load.vertices,
        load.total,
        load.force,
        load.area,
        part_id=load.part_id,
    )


def band(part: BodyPart, at: float = 0.5, width: float = 0.03, total: float = 1.0) -> Load:
    """A ring around a limb, ``width`` (m) wide, centred at fraction ``at`` along its axis."""
    if not 0.0 <= at <= 1.0:
        raise ValueError(f"band at must be in [0, 1] (fraction along the limb), got {at}")
    _check_length("width", width)
    s = part.axial
    s0 = s.min() + at * (s.max() - s.min())
    return from_vertices(
        part,
        np.nonzero(np.abs(s - s0) <= width / 2)[0],
        total,
        "band",
        {"at": float(at), "width": float(width)},
        whole=False,
    )


def letter(
    part: BodyPart,
    char: str = "A",
    uv=(0.5, 0.5),
    height: float = 0.08,
    stroke: float = 0.01,
    angle: float = 0.0,
    total: float = 1.0,
) -> Load:
    """The contour of a bold block letter laid on the chart: centred at ``uv``, ``height`` (m)
    tall, loading vertices within ``stroke / 2`` (m) of the outline. ``angle`` (rad) turns it.
    """
    if not isinstance(char, str) or len(char) != 1 or not char.strip():
        raise ValueError(f"letter needs one visible character, got {char!r}")
    _check_length("height", height)
    _check_length("stroke", stroke)
    surface.point_at_uv(part, uv)  # the centre must be on the chart
    segs = _glyph_segments(char)  # (S, 2, 2), glyph units, height 1, centred
    c, s = math.cos(angle), math.sin(angle)
    rot = np.array([[c, -s], [s, c]])
    segs = segs @ rot.T * (height / part.uv_scale) + np.asarray(uv, float)
    a, b = segs[:, 0], segs[:, 1]
    p = part.uv[:, None, :]
    t = np.clip(((p - a) * (b - a)).sum(-1) / np.maximum(((b - a) ** 2).sum(-1), 1e-300), 0, 1)
    dist = np.linalg.norm(p - (a + t[..., None] * (b - a)), axis=-1).min(1) * part.uv_scale
    hit = np.unique(part.uv_vertex[dist <= stroke / 2])
    return from_vertices(
        part,
        hit,
        total,
        "letter",
        {
            "char": char,
            "uv": [float(x) for x in uv],
            "height": float(height),
            "stroke": float(stroke),
            "angle": float(angle),
        },
        whole=False,
    )


def combine(part: BodyPart, *loads: Load) -> Load:
    """Several loads at once: forces add up."""
    if not loads:
        raise ValueError("combine needs at least one load")
    for i, ld in enumerate(loads):
        if ld.part_id and ld.part_id != part.fingerprint:
            raise ValueError(
                f"combine: load {i} ({ld.kind}) was built on another part than {part.name!r}"
            )
    force = sum(ld.force for ld in loads)
    _check_force(force)
    idx = np.nonzero(force > 0)[0]
    return Load(
        "combined",
        {"loads": [ld.to_dict() for ld in loads]},
        idx,
        float(sum(ld.total for ld in loads)),
        force,
        float(part.vertex_areas[idx].sum()),
        parts=tuple(loads),
        part_id=part.fingerprint,
    )


PRIMITIVES = {
    "disk": disk,
    "ellipse": ellipse,
    "seam_disk": seam_disk,
    "spots": spots,
    "band": band,
    "letter": letter,
}
"""Load primitives by name (configs and the command line resolve through this)."""


def glyph_contours(text: str) -> list[np.ndarray]:
    """The closed outlines ``(K, 2)`` of ``text`` set in a bold sans-serif font (DejaVu Sans Bold,
    which matplotlib ships), in units of the text's height, centred on the origin; a character
    the font lacks is refused (it would be drawn as a box).
    """
    from matplotlib.font_manager import (
        FontProperties,
        findfont,
        get_font,
    )  # deferred: pictures only
    from matplotlib.textpath import TextPath  # deferred: pictures only

    prop = FontProperties(family="DejaVu Sans", weight="bold")
    font = get_font(findfont(prop))
    for char in text:
        if not char.isspace() and font.get_char_index(ord(char)) == 0:
            raise ValueError(
                f"character {char!r} (U+{ord(char):04X}) is not in the letter font "
                f"({font.family_name}); use letters, digits or signs it has"
            )
    path = TextPath((0, 0), text, size=1.0, prop=prop)
    polys = [np.asarray(p) for p in path.to_polygons(closed_only=True) if len(p) > 2]
    if not polys:
        raise ValueError(f"text {text!r} has no outline in the font")
    pts = np.concatenate(polys)
    lo, hi = pts.min(0), pts.max(0)
    scale, centre = 1.0 / (hi[1] - lo[1]), (lo + hi) / 2
    return [(p - centre) * scale for p in polys]


def _glyph_segments(char: str) -> np.ndarray:
    """``(S, 2, 2)`` outline segments of ``char`` (:func:`glyph_contours`)."""
    return np.concatenate([np.stack([p[:-1], p[1:]], 1) for p in glyph_contours(char)])


def _check_total(total) -> float:
    t = float(total)
    if not math.isfinite(t) or t <= 0:
        raise ValueError(f"total force must be finite and > 0 N, got {total}")
    return t


def _check_length(name: str, value) -> None:
    v = float(value)
    if not math.isfinite(v) or v <= 0:
        raise ValueError(f"{name} must be finite and > 0 m, got {value}")


def _check_force(force: np.ndarray) -> None:
    lo, hi = FORCE_RANGE
    if force.max() > hi:
        i = int(force.argmax())
        raise ValueError(
            f"per-vertex force must be <= {hi:g} N (the normalisation range); "
            f"vertex {i} gets {force[i]:.3g} N: spread the load or lower it"
        )
