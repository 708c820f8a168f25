"""Shaded 3D pictures of a pressed body: the deformed part coloured by its displacement, the
objects that press it drawn see-through, one panel per method.

Triangles of every mesh are projected through one camera, lit by a light from the viewer and
drawn back to front in one collection (a painter's algorithm: no OpenGL, so it works on a
headless machine). The camera looks at the contact along the skin's mean outward normal there.
"""

from __future__ import annotations

import pathlib
import textwrap

import numpy as np

from stmpl.metrics import sample_metrics
from stmpl.viz.figures import view_basis
from stmpl.viz.verdict import impossible


def refine(triangles: np.ndarray, values: np.ndarray, levels: int = 2):
    """Split every triangle ``(T, 3, 3)`` with corner ``values`` ``(T, 3)`` into four at its
    edge midpoints, ``levels`` times (a triangle soup, for smooth colours): ``(T 4^L, 3, 3)``,
    ``(T 4^L, 3)``.
    """
    t, v = np.asarray(triangles, float), np.asarray(values, float)
    for _ in range(levels):
        m = 0.5 * (t + t[:, [1, 2, 0]])  # midpoints ab, bc, ca
        mv = 0.5 * (v + v[:, [1, 2, 0]])
        t = np.concatenate(
            [
                np.stack([t[:, 0], m[:, 0], m[:, 2]], 1),
                np.stack([m[:, 0], t[:, 1], m[:, 1]], 1),
                np.stack([m[:, 2], m[:, 1], t[:, 2]], 1),
                m,
            ]
        )
        v = np.concatenate(
            [
                np.stack([v[:, 0], mv[:, 0], mv[:, 2]], 1),
                np.stack([mv[:, 0], v[:, 1], mv[:, 1]], 1),
                np.stack([mv[:, 2], mv[:, 1], v[:, 2]], 1),
                mv,
            ]
        )
    return t, v


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


def draw_meshes(ax, basis: np.ndarray, meshes: list) -> None:
    """Draw ``meshes`` seen through ``basis`` (camera rows: right, up, towards the viewer):
    each a tuple ``(triangles (T, 3, 3), rgba (T, 4) or (4,), cull)``; triangles turned away are
    dropped where ``cull`` is true (closed, opaque meshes).
    """
    from matplotlib.collections import PolyCollection  # deferred: pictures only

    polys, colours, depth = [], [], []
    for triangles, rgba, cull in meshes:
        tri = np.asarray(triangles) @ basis.T
        n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
        n /= np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-300)
        keep = n[:, 2] > 0 if cull else np.ones(len(tri), bool)
        c = np.broadcast_to(np.asarray(rgba, float), (len(tri), 4)).copy()
        n = n * np.where(n[:, 2] < 0, -1.0, 1.0)[:, None]  # the side the viewer sees
        c[:, :3] *= (0.3 + 0.7 * np.clip(n @ LIGHT, 0.0, 1.0))[:, None]
        polys.append(tri[keep, :, :2])
        colours.append(c[keep])
        depth.append(tri[keep, :, 2].mean(1))
    order = np.argsort(np.concatenate(depth))
    colours = np.concatenate(colours)[order]
    ax.add_collection(
        PolyCollection(
            np.concatenate(polys)[order],
            facecolors=colours,
            edgecolors="none",
            # smoothed edges of abutting opaque triangles leave hairline seams; see-through
            # ones unsmoothed would draw their shared edges twice
            antialiaseds=colours[:, 3] < 1,
        )
    )
    ax.set_aspect("equal")
    ax.axis("off")


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


def contact_figure(
    deformations: dict,
    truth=None,
    objects=(),
    path=None,
    dpi: int = 110,
    title: str | None = None,
    failed: dict | None = None,
):
    """A PNG of one pressed scene: a panel per method (``deformations``: name ->
    :class:`~stmpl.scene.Deformation`; ``truth``, e.g. the FEM's, first) showing the deformed
    skin in 3D coloured by |u| (mm, one scale for all panels) with the ``objects``
    (``trimesh`` meshes in body coordinates) drawn see-through, the method's time and, against
    ``truth``, its relative mean error and its peak. Where answers carry a contact pressure
    (a scene given by an object's pose), a second row shows it on the skin, in kPa on one
    scale. ``failed``: name -> why, the solves that gave no answer, each a panel of the skin at
    rest that says so in red.
    """
    import matplotlib  # deferred: pictures only
    from matplotlib.figure import Figure  # deferred: pictures only (no pyplot: 0.2-0.3 s less)

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
    cmap = matplotlib.colormaps["YlOrRd"]  # light where still: the shading shows shape
    shapes = [np.asarray(m.vertices)[np.asarray(m.faces)] for m in objects]
    faces = skin_faces(part)
    skins = {
        name: part.vertices[faces]
        if isinstance(d, str)
        else (part.vertices + scale * d.displacement)[faces]
        for name, d in rows
    }
    window = fitted_window([*skins.values(), *shapes], basis, centre, reach)
    x0, x1, y0, y1 = window
    pressed = {  # the contact pressure (kPa) of each answer that has one: a second row
        name: d.pressure * 1e-3
        for name, d in rows
        if not isinstance(d, str) and d.force is not None
    }
    nrow = 2 if pressed else 1
    panel = 4.4  # inches across a panel
    width = panel * len(rows) + 1.6
    text = (title or _title(first.scene, first.info.get("force_control"))) + (
        f"\n(displacements drawn {scale:g}x their size; colours true)"
        if scale > 1
        else "\n(displacements drawn true to scale)"
    )
    chars = int(13 * width)  # what a line of 10 pt text holds across the figure
    text = "\n".join(textwrap.fill(line, chars) for line in text.splitlines())
    titles = {name: _panel_title(name, d, truth) for name, d in rows}
    lines = text.count("\n") + 1 + max(t[0].count("\n") + 1 for t in titles.values())
    above, foot = 0.3 + LINE * lines, 0.15  # inches for the titles, and below
    between = 0.35 if pressed else 0.0  # the pressure row's own line
    aspect = (y1 - y0) / (x1 - x0)
    right, wspace, ratios = (
        1 - 0.8 / width,
        0.05,
        [1] * len(rows) + [0.05],
    )  # 0.8 in: the bar's label
    # a panel's width as laid out (less than ``panel``: the gaps and the colour bar), so that
    # the figure is as tall as the window's shape needs at that width
    cells = (right - 0.01) / (1 + wspace * (len(ratios) - 1) / len(ratios))
    drawn = width * cells / sum(ratios)
    height = drawn * aspect * nrow + above + between + foot
    fig = Figure(figsize=(width, height))
    grid = fig.add_gridspec(
        nrow,
        len(rows) + 1,
        width_ratios=ratios,
        left=0.01,
        right=right,
        bottom=foot / height,
        top=1 - above / height,
        wspace=wspace,
        hspace=between / (drawn * aspect),
    )
    axes = [[fig.add_subplot(grid[r, k]) for k in range(len(rows))] for r in range(nrow)]
    seen = [(m[in_window(m, basis, window)], (0.6, 0.8, 1.0, 0.3), True) for m in shapes]
    peak = max([float(p.max()) for p in pressed.values()] + [1e-6])
    blues = matplotlib.colormaps["PuBu"]
    for k, (name, d) in enumerate(rows):
        skin = skins[name]
        near = in_window(skin, basis, window)  # refined only where it is seen
        ax = axes[0][k]
        if isinstance(d, str):  # a solve that failed: the skin at rest
            draw_meshes(ax, basis, [(skin[near], (0.85, 0.85, 0.85, 1.0), True), *seen])
        else:
            tri, val = refine(skin[near], d.magnitude[faces][near] * 1e3)
            draw_meshes(ax, basis, [(tri, cmap(val.mean(1) / top), True), *seen])  # far side hidden
        head, color = titles[name]
        ax.set_title(head, fontsize=10, color=color)
        if pressed:  # the skin alone, coloured by its contact pressure (none: grey)
            ax = axes[1][k]
            if name in pressed:
                tri, val = refine(skin[near], pressed[name][faces][near])
                draw_meshes(ax, basis, [(tri, blues(val.mean(1) / peak), True)])
                ax.set_title(f"contact pressure, peak {pressed[name].max():.3g} kPa", fontsize=9)
            else:
                draw_meshes(ax, basis, [(skin[near], (0.85, 0.85, 0.85, 1.0), True)])
                ax.set_title(
                    "no answer" if isinstance(d, str) else "no contact pressure", fontsize=9
                )
        for r in range(nrow):
            axes[r][k].set_xlim(x0, x1)
            axes[r][k].set_ylim(y0, y1)
    sm = matplotlib.cm.ScalarMappable(matplotlib.colors.Normalize(0, top), cmap)
    fig.colorbar(sm, cax=fig.add_subplot(grid[0, -1]), label="displacement |u| (mm)")
    if pressed:
        sm = matplotlib.cm.ScalarMappable(matplotlib.colors.Normalize(0, peak), blues)
        fig.colorbar(sm, cax=fig.add_subplot(grid[1, -1]), label="contact pressure (kPa)")
    fig.suptitle(text, y=1 - 0.1 / height, va="top", fontsize=10)
    if path is not None:
        pathlib.Path(path).parent.mkdir(parents=True, exist_ok=True)
        fig.savefig(path, dpi=dpi)
    return fig


LINE = 0.17
"""Inches a line of 10 pt text takes."""


def _panel_title(name: str, d, truth) -> tuple[str, str]:
    """A panel's title and its colour: the method, its time, its deepest displacement, its
    error against ``truth``, and in red why it is not to be trusted; or, for a solve that
    failed (``d`` its reason), that it gave no answer and why.
    """
    red = "#a00000"
    if isinstance(d, str):
        why = textwrap.fill(d, 44, max_lines=3, placeholder=" ...")
        return f"{name}: failed, no answer\n{why}", red
    ms, fc = d.info.get("seconds"), d.info.get("force_control")
    head = (
        f"{name}"
        + (" (in the mirror)" if d.info.get("mirrored") else "")
        + (f", {duration(ms)}" if ms is not None and not fc else "")
    )
    if fc:  # the answer's time is the whole search's
        head += f", {duration(fc['seconds'])} to meet {fc['force']:g} N"
    lines = [head, f"deepest {d.magnitude.max() * 1e3:.2f} mm"]
    if d.reaction is not None:  # a pose's answer: the force it meets
        lines[-1] += f", reaction {d.reaction:.3g} N"
    if truth is not None and d is not truth:
        m = sample_metrics(truth.displacement, d.displacement)
        lines.append(f"error {m['rel_mee']:.2f} % of the deepest, peak {m['peak_err']:+.1f} %")
    warn = _warning(d)
    if warn:
        lines.append(warn)
    return "\n".join(lines), red if warn else "black"


def duration(seconds: float) -> str:
    """``12.3 ms`` or ``4.5 s``."""
    return f"{seconds * 1e3:.1f} ms" if seconds < 1 else f"{seconds:.1f} s"


def _title(scene, forced: dict | None = None) -> str:
    """The picture's title: the part, its tissue and what presses it; ``forced``: the answer's
    ``info["force_control"]`` (the object pressed on until it met a force).
    """
    load = scene.load
    if scene.pose is not None and forced:
        text = (
            f"{', '.join(scene.pose.names()) or 'an object'} pressed on "
            f"{forced['moved_mm']:.2f} mm from where it was put, until it meets "
            f"{forced['force']:g} N"
        )
    elif scene.pose is not None:
        text = (
            f"{', '.join(scene.pose.names()) or 'an object'} at its pose, "
            f"{scene.pose.nearest()}: the force is answered"
        )
    else:
        text = (
            load.source.summary()
            if load is not None and load.source is not None
            else (load.summary() if load is not None else f"{scene.total_force:g} N")
        )
    return (
        f"{scene.part.name} ({scene.part.n_vertices} vertices){body_words(scene.part)}, "
        f"{1e3 * float(np.median(scene.thickness)):.1f} mm tissue\n{text}"
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
