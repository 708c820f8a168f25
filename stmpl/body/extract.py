"""Cutting a part out of a whole body mesh: the faces of one UV chart and one connected piece,
the chart fitted into the unit square.
"""

from __future__ import annotations

import numpy as np

from stmpl.geometry import boundary_loops, largest_component, triangle_areas_of, vertex_normals
from stmpl.part import CHART_MARGIN, BodyPart


def extract_part(
    name: str,
    vertices: np.ndarray,
    faces: np.ndarray,
    uv: np.ndarray,
    face_uv: np.ndarray,
    vertex_mask: np.ndarray,
    axis: np.ndarray | None = None,
    source: dict | None = None,
) -> BodyPart:
    """Cut a part out of a whole body mesh.

    Args:
        vertices: ``(V, 3)`` body rest positions, m. faces: ``(F, 3)``. uv: ``(T, 2)`` atlas UVs.
        face_uv: ``(F, 3)`` UV corner indices. vertex_mask: ``(V,)`` bool, the part's vertices.
        axis: ``(K, 3)`` limb centre line or ``None``.

    Faces with all three corners selected are kept; of those, the faces of the largest UV
    island (so the part has one chart), and of those the largest connected piece in 3D.
    """
    vertices = np.asarray(vertices, float)
    faces = np.asarray(faces, np.int64)
    body_normals = vertex_normals(vertices, faces)
    fsel = np.asarray(vertex_mask, bool)[faces].all(axis=1)
    if not fsel.any():
        raise ValueError(f"part {name!r}: the selection contains no whole face")
    face_uv = np.asarray(face_uv, np.int64)
    # one UV chart: keep faces of the largest UV island (stray corners of a neighbouring
    # island would stretch the chart), then the largest connected piece in 3D
    fsel[fsel] = largest_component(face_uv[fsel], len(uv))
    fsel[fsel] = largest_component(faces[fsel], len(vertices))
    pf, puv = faces[fsel], face_uv[fsel]
    used = np.unique(pf)
    vmap = -np.ones(len(vertices), np.int64)
    vmap[used] = np.arange(len(used))
    used_uv = np.unique(puv)
    uvmap = -np.ones(len(uv), np.int64)
    uvmap[used_uv] = np.arange(len(used_uv))
    lf, luv = vmap[pf], uvmap[puv]
    uv_vertex = np.zeros(len(used_uv), np.int64)
    uv_vertex[luv.ravel()] = lf.ravel()
    v = vertices[used]
    chart, scale = normalise_chart(np.asarray(uv, float)[used_uv], v, lf, luv)
    return BodyPart(
        name=name,
        vertices=v,
        faces=lf,
        normals=body_normals[used],
        uv=chart,
        face_uv=luv,
        uv_vertex=uv_vertex,
        uv_scale=scale,
        rims=boundary_loops(lf),
        axis=axis,
        body_index=used,
        source=dict(source or {}),
    )


def normalise_chart(
    uv: np.ndarray,
    vertices: np.ndarray,
    faces: np.ndarray,
    face_uv: np.ndarray,
    margin: float = CHART_MARGIN,
) -> tuple[np.ndarray, float]:
    """Fit UVs ``(T, 2)`` into ``[margin, 1 - margin]^2`` (aspect kept, centred).

    Returns the new UVs and the metres per chart unit (sqrt of 3D area / UV area).
    """
    lo, hi = uv.min(axis=0), uv.max(axis=0)
    span = float((hi - lo).max())
    if span <= 0:
        raise ValueError("degenerate UV chart (zero extent)")
    s = (1.0 - 2 * margin) / span
    out = (uv - lo) * s + (1.0 - (hi - lo) * s) / 2.0
    a3 = triangle_areas_of(vertices[faces]).sum()
    a2 = triangle_areas_of(np.concatenate([out[face_uv], np.zeros(face_uv.shape + (1,))], -1)).sum()
    return out, float(np.sqrt(a3 / a2))
