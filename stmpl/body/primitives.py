"""Analytic parts: a tube (an arm-like cylinder with a lengthwise UV seam) and a flat sheet.

Used for verification, where geodesics, areas and elastic solutions are known in closed form.
"""

from __future__ import annotations

import numpy as np

from stmpl.body.extract import normalise_chart
from stmpl.geometry import boundary_loops
from stmpl.part import BodyPart


def tube(
    radius: float = 0.04,
    length: float = 0.3,
    n_around: int = 24,
    n_along: int = 30,
    taper: float = 0.0,
) -> BodyPart:
    """An open cylinder along +z with a UV seam at angle 0 (``u`` around, ``v`` along).

    Args:
        radius: m at z = 0; ``taper`` shrinks it linearly to ``radius * (1 - taper)`` at the end.
        length: m. n_around, n_along: vertices around and rings along.
    """
    if n_around < 3 or n_along < 2 or radius <= 0 or length <= 0 or not 0 <= taper < 1:
        raise ValueError(
            "tube needs n_around >= 3, n_along >= 2, radius > 0, length > 0, 0 <= taper < 1"
        )
    th = 2 * np.pi * np.arange(n_around) / n_around
    z = np.linspace(0.0, length, n_along)
    r = radius * (1 - taper * z / length)
    v = np.stack(
        [np.outer(r, np.cos(th)), np.outer(r, np.sin(th)), np.repeat(z[:, None], n_around, 1)], -1
    ).reshape(-1, 3)
    i, j = np.meshgrid(np.arange(n_along - 1), np.arange(n_around), indexing="ij")
    a, b = i * n_around + j, i * n_around + (j + 1) % n_around
    c, d = a + n_around, b + n_around
    faces = np.concatenate(
        [np.stack([a, b, d], -1).reshape(-1, 3), np.stack([a, d, c], -1).reshape(-1, 3)]
    )
    # UV corners: n_around + 1 columns, the last one duplicates the seam column at u = 1
    ua = (np.arange(n_around + 1) / n_around) * 2 * np.pi * radius
    uvg = np.stack(np.meshgrid(ua, z, indexing="xy"), -1).reshape(-1, 2)
    ju = np.where((j + 1) % n_around == 0, n_around, j + 1)
    ua_, ub_ = i * (n_around + 1) + j, i * (n_around + 1) + ju
    uc_, ud_ = ua_ + n_around + 1, ub_ + n_around + 1
    face_uv = np.concatenate(
        [np.stack([ua_, ub_, ud_], -1).reshape(-1, 3), np.stack([ua_, ud_, uc_], -1).reshape(-1, 3)]
    )
    col = np.arange(n_around + 1) % n_around
    uv_vertex = (np.arange(n_along)[:, None] * n_around + col[None]).ravel()
    normals = np.concatenate(
        [v[:, :2] / np.linalg.norm(v[:, :2], axis=1, keepdims=True), np.zeros((len(v), 1))], 1
    )
    uv, scale = normalise_chart(uvg, v, faces, face_uv)
    rims = (np.arange(n_around), np.arange(n_around)[::-1] + (n_along - 1) * n_around)
    axis = np.array([[0.0, 0.0, 0.0], [0.0, 0.0, length]])
    return BodyPart(
        name="tube",
        vertices=v,
        faces=faces,
        normals=normals,
        uv=uv,
        face_uv=face_uv,
        uv_vertex=uv_vertex,
        uv_scale=scale,
        rims=rims,
        axis=axis,
        source={
            "body": "primitive",
            "part": "tube",
            "options": dict(
                radius=radius, length=length, n_around=n_around, n_along=n_along, taper=taper
            ),
        },
    )


def sheet(width: float = 0.2, height: float = 0.2, nx: int = 21, ny: int = 21) -> BodyPart:
    """A flat rectangle in the z = 0 plane, normal +z, no seam, ``nx`` by ``ny`` vertices."""
    return grid(
        np.linspace(-width / 2, width / 2, nx),
        np.linspace(-height / 2, height / 2, ny),
        options=dict(width=width, height=height, nx=nx, ny=ny),
    )


def grid(xs, ys, options: dict | None = None) -> BodyPart:
    """A flat sheet in the z = 0 plane, normal +z, whose vertices stand on the lines ``x = xs``
    and ``y = ys`` (m, each rising strictly): fine where a verification needs it (under an
    indenter), coarse far away.
    """
    xs, ys = np.asarray(xs, dtype=float), np.asarray(ys, dtype=float)
    for name, c in (("xs", xs), ("ys", ys)):
        if c.ndim != 1 or len(c) < 2 or not np.all(np.isfinite(c)) or np.any(np.diff(c) <= 0):
            raise ValueError(f"{name} must be at least two finite coordinates rising strictly")
    nx, ny = len(xs), len(ys)
    x, y = np.meshgrid(xs, ys)
    v = np.stack([x.ravel(), y.ravel(), np.zeros(x.size)], 1)
    i, j = np.meshgrid(np.arange(ny - 1), np.arange(nx - 1), indexing="ij")
    a = i * nx + j
    faces = np.concatenate(
        [
            np.stack([a, a + 1, a + nx + 1], -1).reshape(-1, 3),
            np.stack([a, a + nx + 1, a + nx], -1).reshape(-1, 3),
        ]
    )
    uv, scale = normalise_chart(v[:, :2], v, faces, faces)
    normals = np.tile([0.0, 0.0, 1.0], (len(v), 1))
    return BodyPart(
        name="sheet",
        vertices=v,
        faces=faces,
        normals=normals,
        uv=uv,
        face_uv=faces,
        uv_vertex=np.arange(len(v)),
        uv_scale=scale,
        rims=boundary_loops(faces),
        source={
            "body": "primitive",
            "part": "sheet" if options else "grid",
            "options": options or dict(xs=xs.tolist(), ys=ys.tolist()),
        },
    )
