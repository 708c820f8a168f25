"""Pictures (PNG) and mesh export (PLY / OBJ / GLB with per-vertex colours).

3D views are drawn with matplotlib as flat-shaded triangles sorted back to front (no OpenGL
needed, so they work on a headless machine). The camera looks at the load (or across the part).
"""

from __future__ import annotations

import pathlib

import numpy as np

from stmpl.part import BodyPart
from stmpl.viz.colours import RAMPS, ramp
from stmpl.viz.meshfile import glb_bytes, ply_bytes


def pyplot():
    import matplotlib  # deferred: pictures only

    matplotlib.use("Agg", force=False)
    import matplotlib.pyplot as plt  # deferred: pictures only

    return plt


def view_basis(part: BodyPart, focus: np.ndarray | None = None) -> np.ndarray:
    """``(3, 3)`` camera rows (right, up, towards the viewer): the part's long axis runs across,
    the camera faces the outward normal at ``focus`` (vertex weights ``(N,)``) if given.
    """
    x = part.vertices - part.vertices.mean(0)
    pcs = np.linalg.svd(x, full_matrices=False)[2]
    if focus is not None and np.asarray(focus).sum() > 0:
        w = np.asarray(focus, float)
        toward = (w[:, None] * part.normals).sum(0)
    else:
        toward = pcs[2]
    toward /= np.linalg.norm(toward)
    right = pcs[0] - (pcs[0] @ toward) * toward
    right /= np.linalg.norm(right)
    return np.stack([right, np.cross(toward, right), toward])


def draw_part(
    ax,
    part: BodyPart,
    values: np.ndarray,
    basis: np.ndarray,
    cmap="viridis",
    vmin=None,
    vmax=None,
    vertices: np.ndarray | None = None,
):
    """Draw the part seen through ``basis`` coloured by per-vertex ``values`` ``(N,)``."""
    import matplotlib  # deferred: pictures only
    import matplotlib.cm as cm  # deferred: pictures only
    import matplotlib.colors as mcolors  # deferred: pictures only
    from matplotlib.collections import PolyCollection  # deferred: pictures only

    v = (part.vertices if vertices is None else vertices) @ basis.T
    tri = v[part.faces]
    n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    n /= np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-300)
    front = n[:, 2] > 0
    order = np.argsort(tri[:, :, 2].mean(1))
    order = order[front[order]]
    norm = mcolors.Normalize(
        vmin=np.min(values) if vmin is None else vmin, vmax=np.max(values) if vmax is None else vmax
    )
    rgba = matplotlib.colormaps[cmap](norm(np.asarray(values)[part.faces].mean(1)))
    shade = 0.45 + 0.55 * n[:, 2:3]
    rgba[:, :3] *= shade
    pc = PolyCollection(
        tri[order, :, :2], facecolors=rgba[order], edgecolors=(0, 0, 0, 0.08), linewidths=0.2
    )
    ax.add_collection(pc)
    ax.set_xlim(v[:, 0].min() - 0.01, v[:, 0].max() + 0.01)
    ax.set_ylim(v[:, 1].min() - 0.01, v[:, 1].max() + 0.01)
    ax.set_aspect("equal")
    ax.axis("off")
    return cm.ScalarMappable(norm=norm, cmap=cmap)


def draw_uv(
    ax, part: BodyPart, values: np.ndarray, size: int = 256, cmap="viridis", vmin=None, vmax=None
):
    """Show per-vertex ``values`` ``(N,)`` as the UV image a UV-UNet sees (chart only)."""
    import torch  # deferred: about a second to import; the core's types do not need it

    from stmpl.uv import uv_map  # deferred: a torch module, for the UV chart's pictures only

    m = uv_map(part, size)
    img = m.rasterise(torch.tensor(np.array(values, float)[:, None])).numpy()[0]
    img = np.where(m.mask.numpy(), img, np.nan)
    im = ax.imshow(img, cmap=cmap, vmin=vmin, vmax=vmax, extent=(0, 1, 0, 1), origin="upper")
    ax.set_xticks([])
    ax.set_yticks([])
    return im


def scene_figure(scene, path=None, size: int = 256, dpi: int = 110):
    """A PNG of a scene: the part in 3D from two sides coloured by force (top) and thickness
    (bottom), with the matching UV images on the right. Returns the figure (saved if ``path``).
    """
    plt = pyplot()
    part = scene.part
    force, thick = np.asarray(scene.force), np.asarray(scene.thickness) * 1e3
    front = view_basis(part, scene.force if scene.force.sum() > 0 else None)
    back = front * np.array([[-1.0], [1.0], [-1.0]])
    fig, axes = plt.subplots(
        2, 3, figsize=(13, 7.5), gridspec_kw={"width_ratios": [1.25, 1.25, 1.0]}
    )
    tmin, tmax = (thick.min() - 0.5, thick.max() + 0.5) if np.ptp(thick) < 1e-9 else (None, None)
    rows = [
        ("force per vertex (N)", force, "inferno", 0.0, max(force.max(), 1e-9)),
        ("tissue thickness (mm)", thick, "viridis", tmin, tmax),
    ]
    for r, (label, val, cmap, lo, hi) in enumerate(rows):
        draw_part(axes[r, 0], part, val, front, cmap, lo, hi)
        draw_part(axes[r, 1], part, val, back, cmap, lo, hi)
        im = draw_uv(axes[r, 2], part, val, size, cmap, lo, hi)
        fig.colorbar(im, ax=axes[r, 2], fraction=0.046, pad=0.04, label=label)
        axes[r, 0].set_title(f"{label}: loaded side")
        axes[r, 1].set_title("opposite side")
        axes[r, 2].set_title(f"UV image {size}x{size}")
    title = f"{part.name} ({part.n_vertices} vertices, {part.n_faces} faces)"
    if scene.load is not None:
        title += " | " + scene.load.summary()
    fig.suptitle(title)
    return save_figure(fig, path, dpi)


def save_figure(fig, path, dpi: int):
    """Lay out ``fig``; save and close it when a ``path`` is given. Returns the figure."""
    top = 1.0 - 0.45 / fig.get_figheight() if fig._suptitle is not None else 1.0
    fig.tight_layout(rect=(0.0, 0.0, 1.0, top))  # room for the suptitle
    if path is not None:
        pathlib.Path(path).parent.mkdir(parents=True, exist_ok=True)
        fig.savefig(path, dpi=dpi)
        pyplot().close(fig)
    return fig


def vertex_colors(values: np.ndarray, cmap="YlOrRd", vmin=None, vmax=None) -> np.ndarray:
    """``(N, 4)`` uint8 RGBA colours of per-vertex ``values`` ``(N,)`` from ``vmin`` (default:
    their least) to ``vmax`` (their most): our own ramps (:mod:`stmpl.viz.colours`, the
    pictures' colours, no plotting library) or any of matplotlib's colour maps by name.
    """
    values = np.asarray(values, float)
    lo = values.min() if vmin is None else vmin
    hi = values.max() if vmax is None else vmax
    t = (values - lo) / (hi - lo) if hi > lo else np.zeros_like(values)
    if cmap in RAMPS:
        rgb = ramp(cmap, t)
    else:
        import matplotlib  # deferred: only for a colour map of its own

        rgb = matplotlib.colormaps[cmap](np.clip(t, 0.0, 1.0))[:, :3]
    rgba = np.concatenate([rgb, np.ones((len(values), 1))], 1)
    return (rgba * 255).round().astype(np.uint8)


def mesh_bytes(mesh, fmt: str, facts: dict | None = None) -> bytes:
    """``mesh`` (a trimesh mesh, its vertex colours kept where it has them) as a file:
    :func:`mesh_file`.
    """
    visual = getattr(mesh, "visual", None)
    colors = visual.vertex_colors if getattr(visual, "kind", None) == "vertex" else None
    return mesh_file(mesh.vertices, mesh.faces, colors, fmt, facts)


def mesh_file(vertices, faces, colors, fmt: str, facts: dict | None = None) -> bytes:
    """A mesh (``vertices`` ``(V, 3)`` m, ``faces`` ``(F, 3)``, optional RGBA uint8 ``colors``
    ``(V, 4)``) as a ``ply``, ``obj`` or ``glb`` file, carrying ``facts`` (what the answer is
    and whether it can be trusted: ``{key: text or number}``): in a GLB as the ``stmpl`` entry
    of the scene's extras (glTF's own place for application data, :func:`glb_extras`); in a
    PLY as ``comment stmpl KEY: VALUE`` header lines; in an OBJ as ``# stmpl`` lines.
    """
    if fmt == "ply":
        return ply_bytes(vertices, faces, colors, _comments(facts))
    if fmt == "glb":
        body = {"name": "body", "vertices": vertices, "faces": faces, "colors": colors}
        return glb_bytes([body], glb_extras(facts))
    if fmt != "obj":
        raise ValueError(f"mesh export supports ply, obj, glb; got {fmt!r}")
    import trimesh  # deferred: mesh files only

    mesh = trimesh.Trimesh(vertices, faces, process=False)
    if colors is not None:
        mesh.visual.vertex_colors = colors
    return (
        "".join(f"# {c}\n" for c in _comments(facts)).encode()
        + mesh.export(file_type="obj").encode()
    )


def export_mesh(
    part: BodyPart,
    path,
    values: np.ndarray | None = None,
    vertices: np.ndarray | None = None,
    cmap="YlOrRd",
    facts: dict | None = None,
) -> pathlib.Path:
    """Write the part (optionally moved to ``vertices`` ``(N, 3)``) with per-vertex colours of
    ``values`` ``(N,)`` to ``.ply``, ``.obj`` or ``.glb``, carrying ``facts``
    (:func:`mesh_file`).
    """
    path = pathlib.Path(path)
    fmt = path.suffix.lower()[1:]
    if fmt not in ("ply", "obj", "glb"):
        raise ValueError(f"mesh export supports .ply, .obj, .glb; got {path.suffix!r}")
    colors = None
    if values is not None:
        values = np.asarray(values, float)
        if values.shape != (part.n_vertices,):
            raise ValueError(f"values must have shape ({part.n_vertices},), got {values.shape}")
        colors = vertex_colors(values, cmap)
    v = part.vertices if vertices is None else np.asarray(vertices)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_bytes(mesh_file(v, part.faces, colors, fmt, facts))
    return path


def glb_extras(facts: dict | None) -> dict:
    """``facts`` as a GLB scene's extras: ``{"stmpl": {key: value}}``."""
    return {"stmpl": {str(k): v for k, v in (facts or {}).items()}}


def _comments(facts: dict | None) -> list[str]:
    """``facts`` as a PLY's or OBJ's comment lines: ``stmpl KEY: VALUE``."""
    return [f"stmpl {k}: {' '.join(str(v).split())}" for k, v in (facts or {}).items()]


def prediction_figure(
    deformations: dict,
    truth=None,
    path=None,
    size: int = 256,
    dpi: int = 100,
    shared_error_scale: bool = False,
):
    """A PNG comparing predictions of one scene: per predictor (a row) the deformed skin around
    the load coloured by |u| (mm, true scale) and its UV image; with ``truth`` (a
    :class:`~stmpl.scene.Deformation`, e.g. the FEM's) also the UV image of the error |u - u*|
    (mm) with its mean over the moving vertices and its largest value in the title, each row on
    its own colour scale (one shared scale hides the errors of good models next to a poor one),
    or with ``shared_error_scale`` on one. ``deformations``: name -> Deformation, all of the same
    scene.
    """
    plt = pyplot()

    items = list(deformations.items())
    if not items:
        raise ValueError("no deformations to draw")
    scene = items[0][1].scene
    part = scene.part
    if (
        truth is not None
        and truth.scene is not scene
        and not np.allclose(truth.scene.force, scene.force)
    ):
        raise ValueError("truth is a deformation of another scene")
    rows = items if truth is None or "fem" in deformations else [("fem", truth)] + items
    top = max(max(d.magnitude.max() for _, d in rows) * 1e3, 1e-9)
    w = np.asarray(scene.force, float)
    c = (part.vertices * w[:, None]).sum(0) / max(w.sum(), 1e-300)
    area = scene.load.area if scene.load is not None else float(part.vertex_areas[w > 0].sum())
    reach = max(3.0 * np.sqrt(area / np.pi), 0.03)
    front = view_basis(part, scene.force if w.sum() > 0 else None)
    cx, cy = (c @ front.T)[:2]
    ncol = 3 if truth is not None else 2
    fig, axes = plt.subplots(len(rows), ncol, figsize=(4.6 * ncol, 3.9 * len(rows)), squeeze=False)
    err_top = None
    if truth is not None:
        err_top = max(
            max(np.linalg.norm(d.displacement - truth.displacement, axis=1).max() for _, d in rows)
            * 1e3,
            1e-9,
        )
    for (name, d), ax in zip(rows, axes):
        mag = d.magnitude * 1e3
        sm = draw_part(ax[0], part, mag, front, "inferno", 0.0, top, vertices=d.vertices)
        ax[0].set_xlim(cx - reach, cx + reach)
        ax[0].set_ylim(cy - reach, cy + reach)
        ms = d.info.get("seconds")
        ax[0].set_title(
            f"{name}: max |u| {mag.max():.2f} mm"
            + (f", {1e3 * ms:.1f} ms" if ms is not None else "")
        )
        fig.colorbar(sm, ax=ax[0], fraction=0.046, pad=0.04, label="|u| (mm)")
        im = draw_uv(ax[1], part, mag, size, "inferno", 0.0, top)
        ax[1].set_title("|u| in UV")
        fig.colorbar(im, ax=ax[1], fraction=0.046, pad=0.04, label="mm")
        if truth is not None and d is truth:
            ax[2].axis("off")
            ax[2].text(0.5, 0.5, "the reference", ha="center", va="center")
        elif truth is not None:
            err = np.linalg.norm(d.displacement - truth.displacement, axis=1) * 1e3
            active = truth.magnitude * 1e3 > 0.001
            im = draw_uv(
                ax[2],
                part,
                err,
                size,
                "magma",
                0.0,
                err_top if shared_error_scale else max(err.max(), 1e-9),
            )
            mee = err[active].mean() if active.any() else float("nan")
            ax[2].set_title(f"error |u - u_fem|: MEE {mee:.3f}, max {err.max():.3f} mm")
            fig.colorbar(im, ax=ax[2], fraction=0.046, pad=0.04, label="mm")
    title = f"{part.name}"
    if scene.load is not None:
        title += " | " + scene.load.summary()
    fig.suptitle(title)
    return save_figure(fig, path, dpi)
