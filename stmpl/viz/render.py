"""Shaded 3D pictures of a pressed body: the deformed part coloured by its displacement, the
objects that press it drawn see-through, one panel per method.

Every mesh is projected through one camera and drawn by a software rasteriser
(:mod:`stmpl.viz.raster`: a depth buffer, colours and light interpolated across each triangle)
on a page of text and colour bars drawn with Pillow (:mod:`stmpl.viz.page`): no OpenGL and no
plotting library, so it works on a headless machine and costs the main job no import of one.
The camera looks at the contact along the skin's mean outward normal there.
"""

from __future__ import annotations

import dataclasses
import pathlib
import textwrap

import numpy as np
from PIL import Image, ImageDraw

from stmpl.geometry import vertex_normals
from stmpl.metrics import sample_metrics
from stmpl.viz import page
from stmpl.viz.colours import ramp
from stmpl.viz.figures import view_basis
from stmpl.viz.raster import Raster
from stmpl.viz.verdict import impossible

LIGHT = np.array([-0.35, 0.55, 0.76]) / np.linalg.norm([-0.35, 0.55, 0.76])
"""Light direction in camera coordinates (right, up, towards the viewer): from the upper left,
so the limb's roundness and the dent read as shape."""
TILT = (np.radians(28.0), np.radians(18.0))
"""Camera turn (about its up axis) and tilt (about its right axis), so a limb recedes in depth
instead of lying flat across the picture."""
EXAGGERATION = 3.0
"""Pictures draw every displacement this many times its size, so that a dent of a millimetre
reads as shape; where that would draw the skin deeper than the tissue is thick, they draw it
true to scale instead. The picture says which."""


def turned(basis: np.ndarray, yaw: float = TILT[0], pitch: float = TILT[1]) -> np.ndarray:
    """The camera ``basis`` turned by ``yaw`` about its up axis, then ``pitch`` about its right
    axis (radians).
    """
    cy, sy, cp, sp = np.cos(yaw), np.sin(yaw), np.cos(pitch), np.sin(pitch)
    r = np.array([[cy, 0, -sy], [0, 1, 0], [sy, 0, cy]])
    r = np.array([[1, 0, 0], [0, cp, -sp], [0, sp, cp]]) @ r
    return r @ basis


SUPERSAMPLE = 2
"""Each pixel of a picture is the mean of ``SUPERSAMPLE`` squared drawn ones: smooth outlines."""
GLASS = ((0.6, 0.8, 1.0), 0.3)
"""The colour and opacity of the objects that press, drawn over the skin."""
GREY = (0.85, 0.85, 0.85)
"""The skin where a panel has no values to colour it by."""


def shade(normals: np.ndarray) -> np.ndarray:
    """``(N,)`` the light on surfaces of unit ``normals`` ``(N, 3)`` (camera coordinates): 0.3
    from all around and up to 0.7 from :data:`LIGHT`.
    """
    return 0.3 + 0.7 * np.clip(normals @ LIGHT, 0.0, 1.0)


@dataclasses.dataclass
class View:
    """A camera: ``basis`` (rows: right, up, towards the viewer) looking at ``window``
    ``(x0, x1, y0, y1)`` (m, camera coordinates), drawn ``width`` x ``height`` pixels.
    """

    basis: np.ndarray
    window: tuple
    width: int
    height: int

    def project(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``(xy (..., 2) supersampled pixels, depth (...) m)`` of ``points`` ``(..., 3)``."""
        cam = np.asarray(points, float) @ self.basis.T
        x0, x1, y0, y1 = self.window
        xy = np.stack(
            [
                (cam[..., 0] - x0) / (x1 - x0) * self.width * SUPERSAMPLE,
                (y1 - cam[..., 1]) / (y1 - y0) * self.height * SUPERSAMPLE,
            ],
            -1,
        )
        return xy, cam[..., 2]

    def raster(self) -> Raster:
        """An empty (white) raster of this view, supersampled."""
        return Raster(self.width * SUPERSAMPLE, self.height * SUPERSAMPLE)


def draw_skin(raster: Raster, view: View, vertices: np.ndarray, faces: np.ndarray, rgb) -> None:
    """Draw the skin ``vertices`` ``(N, 3)`` (m), its ``faces`` ``(F, 3)`` that face the viewer,
    each vertex of colour ``rgb`` ``(N, 3)`` (or one ``(3,)``) lit along its normal (the mean
    of its faces' normals, weighted by area): smooth light over the skin's shape.
    """
    vertices = np.asarray(vertices, float)
    tri = vertices[faces]
    toward = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]) @ view.basis[2]
    normals = vertex_normals(vertices, faces) @ view.basis.T  # in camera coordinates
    lit = np.broadcast_to(np.asarray(rgb, float), vertices.shape) * shade(normals)[:, None]
    front = faces[toward > 0]  # faces turned away are hidden by the skin in front of them
    xy, z = view.project(vertices)
    raster.opaque(xy[front], z[front], lit[front])


def draw_glass(raster: Raster, view: View, triangles: np.ndarray) -> None:
    """Draw an object's ``triangles`` ``(T, 3, 3)`` (m) that face the viewer see-through over
    the skin (:data:`GLASS`), each lit along its own normal.
    """
    triangles = np.asarray(triangles, float).reshape(-1, 3, 3)
    tri = triangles @ view.basis.T
    n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    front = n[:, 2] > 0
    n = n[front] / np.maximum(np.linalg.norm(n[front], axis=1, keepdims=True), 1e-300)
    colour, alpha = GLASS
    xy, z = view.project(triangles[front])
    raster.glass(xy, z, np.asarray(colour) * shade(n)[:, None], alpha)


def contact_camera(deformation) -> tuple[np.ndarray, np.ndarray, float]:
    """``(basis, centre (3,), reach m)``: a camera on the loaded skin of a deformation's scene."""
    part = deformation.scene.part
    w = np.asarray(deformation.applied, float)
    basis = view_basis(part, w if w.sum() > 0 else None)
    centre = (part.vertices * w[:, None]).sum(0) / max(w.sum(), 1e-300)
    loaded = part.vertices[w > 0]
    reach = max(0.05, 1.6 * float(np.linalg.norm(loaded - centre, axis=1).max(initial=0.0)))
    return basis, centre, reach


def skin_faces(part) -> np.ndarray:
    """``(F', 3)`` the part's faces less those with all three corners on an open rim: where
    the part was cut from the body such a face spans the cut and, seen from the side, hangs
    off the limb's outline like a stray spike.
    """
    on_rim = np.zeros(part.n_vertices, bool)
    for rim in part.rims:
        on_rim[rim] = True
    return part.faces[~on_rim[part.faces].all(1)]


def in_window(triangles: np.ndarray, basis: np.ndarray, window) -> np.ndarray:
    """``(T,)`` which triangles ``(T, 3, 3)`` seen through ``basis`` reach into ``window``
    ``(x0, x1, y0, y1)`` (m, camera coordinates).
    """
    xy = np.asarray(triangles) @ basis[:2].T
    x0, x1, y0, y1 = window
    return (
        (xy[..., 0].max(1) >= x0)
        & (xy[..., 0].min(1) <= x1)
        & (xy[..., 1].max(1) >= y0)
        & (xy[..., 1].min(1) <= y1)
    )


def fitted_window(triangles: list, basis: np.ndarray, centre, reach: float):
    """``(x0, x1, y0, y1)``: ``reach`` (m) either side of ``centre`` across, and up and down
    only as far as the ``triangles`` (a list of ``(T, 3, 3)``) inside that span reach, so that
    a long limb seen from its side leaves no empty band.
    """
    cx, cy = (np.asarray(centre) @ basis.T)[:2]
    window = (cx - reach, cx + reach, cy - reach, cy + reach)
    ys = [
        (np.asarray(t)[in_window(t, basis, window)] @ basis[1]).ravel() for t in triangles if len(t)
    ]
    ys = np.concatenate(ys) if ys else np.zeros(0)
    if not ys.size:
        return window
    pad = 0.04 * reach
    return (
        cx - reach,
        cx + reach,
        max(ys.min() - pad, cy - reach),
        min(ys.max() + pad, cy + reach),
    )


def _warning(d) -> str | None:
    """The line a panel adds in red when its answer is impossible or outside its envelope."""
    env = d.info.get("envelope")
    why = impossible(d.info)
    if why:
        return textwrap.fill(
            why[0].split(" and the FEM")[0] + ": do not use", 46, break_on_hyphens=False
        )
    if env and not env["inside"]:
        why = env["outside"][0].split(" (")[0].split(": the nearest")[0]
        return textwrap.fill("outside its envelope: " + why, 46, break_on_hyphens=False)
    return None


@dataclasses.dataclass
class Panel:
    """A panel of a picture: its ``title`` in ``colour``, its ``row`` (0: the dents, 1: the
    contact pressure) and ``box`` ``(x0, y0, x1, y1)``, pixels on the page.
    """

    title: str
    colour: str
    row: int
    box: tuple


@dataclasses.dataclass
class Picture:
    """A drawn picture: the ``image``, its ``title``, its ``panels`` and its colour ``bars``
    (``(label, box)``, pixels on the page).
    """

    image: Image.Image
    title: str
    panels: list
    bars: list

    def save(self, path) -> None:
        """Write the picture as a PNG at ``path`` (its folder made if missing)."""
        pathlib.Path(path).parent.mkdir(parents=True, exist_ok=True)
        self.image.save(path, format="PNG")


RED = "#a00000"
"""The colour of a panel's title that says its answer is not to be trusted."""


def contact_figure(
    deformations: dict,
    truth=None,
    objects=(),
    path=None,
    dpi: int = 110,
    title: str | None = None,
    failed: dict | None = None,
    tissue: str | None = None,
) -> Picture:
    """A picture of one pressed scene: a panel per method (``deformations``: name ->
    :class:`~stmpl.scene.Deformation`; ``truth``, e.g. the FEM's, first) showing the deformed
    skin in 3D coloured by |u| (mm, one scale for all panels) with the ``objects`` (meshes in
    body coordinates) drawn see-through, the method's time and, against ``truth``, its relative
    mean error and its peak. Where answers carry a contact pressure (a scene given by an
    object's pose), a second row shows it on the skin, in kPa on one scale. ``failed``: name ->
    why, the solves that gave no answer, each a panel of the skin at rest that says so in red.
    ``tissue``: what the thickness is of, in words, for the title (default: "tissue").
    Written as a PNG at ``path`` if given.
    """
    rows = ([("FEM", truth)] if truth is not None else []) + list(deformations.items())
    if not rows:
        raise ValueError("no deformations to draw")
    first = rows[0][1]
    rows = [(name, why) for name, why in (failed or {}).items()] + rows
    part = first.scene.part
    basis, centre, reach = contact_camera(first)
    basis = turned(basis)
    answered = [d for _, d in rows if not isinstance(d, str)]
    top = max(max(d.magnitude.max() for d in answered) * 1e3, 1e-6)
    depth = 1e3 * float(np.median(first.scene.thickness))
    scale = EXAGGERATION if EXAGGERATION * top <= depth else 1.0
    shapes = [np.asarray(m.vertices)[np.asarray(m.faces)] for m in objects]
    faces = skin_faces(part)
    skins = {
        name: part.vertices if isinstance(d, str) else part.vertices + scale * d.displacement
        for name, d in rows
    }
    window = fitted_window([v[faces] for v in skins.values()] + shapes, basis, centre, reach)
    pressed = {  # the contact pressure (kPa) of each answer that has one: a second row
        name: d.pressure * 1e-3
        for name, d in rows
        if not isinstance(d, str) and d.force is not None
    }
    peak = max([float(p.max()) for p in pressed.values()] + [1e-6])
    x0, x1, y0, y1 = window
    wide = round(4.2 * dpi)  # a panel's pixels across
    view = View(basis, window, wide, max(1, round(wide * (y1 - y0) / (x1 - x0))))
    seen = [m[in_window(m, basis, window)] for m in shapes]

    # the page: the title, a row of panels with their titles, the pressure row, the bars
    big, small = page.points(10, dpi), page.points(9, dpi)
    line = page.line_height(big)
    margin, gap, bar = round(0.1 * dpi), round(0.05 * wide), round(0.05 * wide)
    labels = ["displacement |u| (mm)"] + (["contact pressure (kPa)"] if pressed else [])
    beside = max(page.bar_space(t, lab, big) for t, lab in zip((top, peak), labels))
    width = margin + len(rows) * wide + len(rows) * gap + bar + beside + margin
    text = (title or _title(first.scene, first.info.get("force_control"), tissue)) + (
        f"\n(displacements drawn {scale:g}x their size; colours true)"
        if scale > 1
        else "\n(displacements drawn true to scale)"
    )
    text = page.wrap(text, big, width - 2 * margin)
    titles = {name: _panel_title(name, d, truth) for name, d in rows}
    heads = max(t[0].count("\n") + 1 for t in titles.values())
    tops = [margin + (text.count("\n") + 1) * line + line // 2 + heads * line + 4]
    if pressed:
        tops.append(tops[0] + view.height + page.line_height(small) + 8)
    height = tops[-1] + view.height + margin
    image = Image.new("RGB", (width, height), "white")
    draw = ImageDraw.Draw(image)
    page.write(draw, width / 2, margin, text, big)
    panels = []
    for k, (name, d) in enumerate(rows):
        left = margin + k * (wide + gap)
        skin = skins[name]
        raster = view.raster()
        near = faces[in_window(skin[faces], basis, window)]  # drawn only where it is seen
        if isinstance(d, str):  # a solve that failed: the skin at rest
            draw_skin(raster, view, skin, near, GREY)
        else:
            draw_skin(raster, view, skin, near, ramp("YlOrRd", d.magnitude * 1e3 / top))
        for m in seen:
            draw_glass(raster, view, m)
        image.paste(Image.fromarray(raster.image(SUPERSAMPLE)), (left, tops[0]))
        head, colour = titles[name]
        page.write(
            draw, left + wide / 2, tops[0] - 4 - (head.count("\n") + 1) * line, head, big, colour
        )
        panels.append(Panel(head, colour, 0, (left, tops[0], left + wide, tops[0] + view.height)))
        if pressed:  # the skin alone, coloured by its contact pressure (none: grey)
            raster = view.raster()
            if name in pressed:
                draw_skin(raster, view, skin, near, ramp("PuBu", pressed[name] / peak))
                head = f"contact pressure, peak {pressed[name].max():.3g} kPa"
            else:
                draw_skin(raster, view, skin, near, GREY)
                head = "no answer" if isinstance(d, str) else "no contact pressure"
            image.paste(Image.fromarray(raster.image(SUPERSAMPLE)), (left, tops[1]))
            page.write(draw, left + wide / 2, tops[1] - 4 - page.line_height(small), head, small)
            panels.append(
                Panel(head, "black", 1, (left, tops[1], left + wide, tops[1] + view.height))
            )
    left = margin + len(rows) * (wide + gap)
    bars = []
    for r, (t, name, label) in enumerate(zip((top, peak), ("YlOrRd", "PuBu"), labels)):
        box = (left, tops[r], left + bar, tops[r] + view.height)
        page.colour_bar(image, box, name, t, label, big)
        bars.append((label, box))
    panels.sort(key=lambda p: (p.row, p.box[0]))  # the dents, then their pressures
    picture = Picture(image, text, panels, bars)
    if path is not None:
        picture.save(path)
    return picture


def _panel_title(name: str, d, truth) -> tuple[str, str]:
    """A panel's title and its colour: the method, its time, its deepest displacement, its
    error against ``truth``, and in red why it is not to be trusted; or, for a solve that
    failed (``d`` its reason), that it gave no answer and why.
    """
    if isinstance(d, str):
        why = textwrap.fill(d, 44, max_lines=3, placeholder=" ...")
        return f"{name}: failed, no answer\n{why}", RED
    ms, fc = d.info.get("seconds"), d.info.get("force_control")
    head = (
        f"{name}"
        + (" (in the mirror)" if d.info.get("mirrored") else "")
        + (f", {duration(ms)}" if ms is not None and not fc else "")
    )
    if fc:  # the answer's time is the whole search's
        head += f", {duration(fc['seconds'])} to meet {fc['force']:g} N"
    lines = [head, f"deepest {d.magnitude.max() * 1e3:.2f} mm"]
    if d.reaction is not None:  # a pose's answer: the force it meets (a grip's: its squeeze)
        lines[-1] += f", {d.scene.pose.reaction_name} {d.reaction:.3g} N"
    if truth is not None and d is not truth:
        m = sample_metrics(truth.displacement, d.displacement)
        lines.append(f"error {m['rel_mee']:.2f} % of the deepest, peak {m['peak_err']:+.1f} %")
    warn = _warning(d)
    if warn:
        lines.append(warn)
    return "\n".join(lines), RED if warn else "black"


def duration(seconds: float) -> str:
    """``12.3 ms`` or ``4.5 s``."""
    return f"{seconds * 1e3:.1f} ms" if seconds < 1 else f"{seconds:.1f} s"


def _title(scene, forced: dict | None = None, tissue: str | None = None) -> str:
    """The picture's title: the part, its tissue (``tissue``: in words) and what presses it;
    ``forced``: the answer's ``info["force_control"]`` (the object pressed on, or the hand
    closed, until it met a force).
    """
    load = scene.load
    names = ", ".join(scene.pose.names()) if scene.pose is not None else ""
    if scene.pose is not None and forced and scene.pose.closing:
        text = (
            f"{names or 'a hand'} closed {forced['moved_mm']:.2f} mm on from where it was put, "
            f"until it squeezes {forced['force']:g} N"
        )
    elif scene.pose is not None and forced:
        text = (
            f"{names or 'an object'} pressed on {forced['moved_mm']:.2f} mm from where it was "
            f"put, until it meets {forced['force']:g} N"
        )
    elif scene.pose is not None:
        text = f"{names or 'an object'} at its pose, {scene.pose.nearest()}: the force is answered"
    else:
        text = (
            load.source.summary()
            if load is not None and load.source is not None
            else (load.summary() if load is not None else f"{scene.total_force:g} N")
        )
    return (
        f"{scene.part.name} ({scene.part.n_vertices} vertices){body_words(scene.part)}, "
        f"{1e3 * float(np.median(scene.thickness)):.1f} mm {tissue or 'tissue'}\n{text}"
    )


def body_words(part) -> str:
    """`` of anny (weight 0.7, muscle 0.3)``: the body a part comes from and the phenotype
    values that differ from anny's defaults (``" of anny (default body)"`` when none does);
    ``""`` for a part with no body model behind it.
    """
    src = part.source or {}
    body = src.get("body")
    if not body:
        return ""
    phenotype = (src.get("options") or {}).get("phenotype") or {}
    changed = [f"{k} {v:g}" for k, v in phenotype.items() if abs(v - 0.5) > 1e-9]
    if not phenotype:
        return f" of {body}"
    return f" of {body} ({', '.join(changed) if changed else 'default body'})"
