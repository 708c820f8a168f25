"""Pictures of the FEM's tetrahedral tissue shell: a plane section of it (:func:`section`) and a
solve drawn with its section through the load (:func:`deformation_figure`, ``stmpl solve
--out``).
"""

from __future__ import annotations

import numpy as np

from stmpl.viz.figures import draw_part, draw_uv, pyplot, save_figure, view_basis


def section(
    nodes: np.ndarray,
    tets: np.ndarray,
    origin: np.ndarray,
    normal: np.ndarray,
    values: np.ndarray | None = None,
    moved: np.ndarray | None = None,
):
    """Cut a tet mesh by the plane through ``origin`` with unit ``normal`` (m).

    Returns ``(polygons, cell_values)``: one ``(k, 3)`` array (k = 3 or 4) per cut element, at
    the ``moved`` node positions ``(M, 3)`` if given (the same material slice, deformed), and the
    mean of per-node ``values`` ``(M,)`` on each polygon (or ``None``).
    """
    d = (nodes - origin) @ normal
    sd = d[tets]
    cut = np.flatnonzero((sd.min(1) < 0) & (sd.max(1) > 0))
    pos = nodes if moved is None else moved
    polys, vals = [], []
    pairs = [(0, 1), (0, 2), (0, 3), (1, 2), (1, 3), (2, 3)]
    for t in cut:
        pts, vs = [], []
        for a, b in pairs:
            da, db = sd[t, a], sd[t, b]
            if (da < 0) != (db < 0):
                s = da / (da - db)
                i, j = tets[t, a], tets[t, b]
                pts.append(pos[i] + s * (pos[j] - pos[i]))
                if values is not None:
                    vs.append(values[i] + s * (values[j] - values[i]))
        pts = np.array(pts)
        if len(pts) == 4:  # order the quad around its centre
            c = pts.mean(0)
            e1 = pts[0] - c
            e2 = np.cross(normal, e1)
            ang = np.arctan2((pts - c) @ e2, (pts - c) @ e1)
            pts = pts[np.argsort(ang)]
        polys.append(pts)
        vals.append(np.mean(vs) if vs else np.nan)
    return polys, (np.array(vals) if values is not None else None)


def deformation_figure(
    deformation,
    nodes: np.ndarray,
    tets: np.ndarray,
    node_u: np.ndarray,
    path=None,
    size: int = 256,
    dpi: int = 110,
):
    """A PNG of a FEM result: the deformed skin around the load coloured by |u| (mm), its UV
    image, and a section of the tissue shell through the load centre along the limb (rest
    outline in grey, deformed in colour, true scale).

    ``nodes`` ``(M, 3)``, ``tets`` ``(T, 4)``: the shell mesh; ``node_u`` ``(M, 3)``: its
    displacement (m).
    """
    plt = pyplot()
    from matplotlib.collections import PolyCollection  # deferred: pictures only

    scene = deformation.scene
    part = scene.part
    mag = deformation.magnitude * 1e3
    top = max(mag.max(), 1e-9)
    w = np.asarray(scene.force, float)
    c = (part.vertices * w[:, None]).sum(0) / w.sum()
    n = (part.normals * w[:, None]).sum(0)
    n /= np.linalg.norm(n)
    area = scene.load.area if scene.load is not None else float(part.vertex_areas[w > 0].sum())
    reach = max(3.0 * np.sqrt(area / np.pi), 0.03)  # m around the load
    fig = plt.figure(figsize=(13, 9))
    gs = fig.add_gridspec(2, 2, height_ratios=[1.2, 1.0])
    ax3, axuv, axs = fig.add_subplot(gs[0, 0]), fig.add_subplot(gs[0, 1]), fig.add_subplot(gs[1, :])
    front = view_basis(part, scene.force if w.sum() > 0 else None)
    sm = draw_part(ax3, part, mag, front, "inferno", 0.0, top, vertices=deformation.vertices)
    cx, cy = (c @ front.T)[:2]
    ax3.set_xlim(cx - reach, cx + reach)
    ax3.set_ylim(cy - reach, cy + reach)
    fig.colorbar(sm, ax=ax3, fraction=0.046, pad=0.04, label="|u| (mm)")
    ax3.set_title("deformed skin around the load (true scale)")
    im = draw_uv(axuv, part, mag, size, "inferno", 0.0, top)
    fig.colorbar(im, ax=axuv, fraction=0.046, pad=0.04, label="|u| (mm)")
    axuv.set_title(f"UV image {size}x{size}")
    # section through the load centre, containing its inward normal and the limb axis
    if part.axis is not None:
        t = part.axis[-1] - part.axis[0]
    else:
        t = np.cross(n, [0.0, 0.0, 1.0]) if abs(n[2]) < 0.9 else np.cross(n, [1.0, 0.0, 0.0])
    t = t - (t @ n) * n
    t /= np.linalg.norm(t)
    plane = np.cross(n, t)
    near = np.linalg.norm(nodes[tets].mean(1) - c, axis=1) < 1.5 * reach
    sub = tets[near]
    umag = np.linalg.norm(node_u, axis=1) * 1e3
    rest, _ = section(nodes, sub, c, plane)
    moved, vals = section(nodes, sub, c, plane, umag, nodes + node_u)
    to2d = lambda p: np.stack([(p - c) @ t, (p - c) @ n], -1) * 1e3  # noqa: E731
    axs.add_collection(
        PolyCollection(
            [to2d(p) for p in rest],
            facecolors="none",
            edgecolors=(0.4, 0.4, 0.4, 0.6),
            linewidths=0.4,
        )
    )
    pc = PolyCollection(
        [to2d(p) for p in moved],
        array=vals,
        cmap="inferno",
        edgecolors=(0, 0, 0, 0.15),
        linewidths=0.2,
    )
    pc.set_clim(0.0, top)
    axs.add_collection(pc)
    pts = np.concatenate([to2d(p) for p in rest]) if rest else np.zeros((1, 2))
    axs.set_xlim(-1e3 * reach, 1e3 * reach)
    axs.set_ylim(pts[:, 1].min() - 1.0, pts[:, 1].max() + 1.0)
    axs.set_aspect("equal")
    axs.set_xlabel(
        "along the limb (mm)" if part.axis is not None else "across the part, horizontally (mm)"
    )
    axs.set_ylabel("outward (mm)")
    axs.set_title(
        "section through the load centre: tissue at rest (grey) and deformed "
        "(colour); the inner surface is fixed"
    )
    fig.colorbar(pc, ax=axs, fraction=0.02, pad=0.01, label="|u| (mm)")
    title = f"{part.name}: FEM"
    if scene.load is not None:
        title += " | " + scene.load.summary()
    title += f" | max |u| {mag.max():.2f} mm"
    fig.suptitle(title)
    return save_figure(fig, path, dpi)
