"""Geometry on a part's surface: points on it, geodesic distances, tangent frames.

Geodesic distances use the heat method (Crane, Weischedel, Wardetzky 2013,
https://doi.org/10.1145/2516971.2516977) on the cotangent Laplacian ``L`` and lumped mass ``M``:

1. heat flow from the source for a short time ``t = h^2``: ``(M + t L) u = delta``;
2. the unit field pointing away from the source, per face: ``X = -grad u / |grad u|``;
3. the distance whose gradient best matches it: ``L phi = -div X``, shifted so the source is 0.

Both matrices are factorised once per part.
"""

from __future__ import annotations

import weakref
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
from scipy.sparse.linalg import factorized

from stmpl.part import BodyPart


@dataclass(frozen=True)
class SurfacePoint:
    """A point on a part: face index, barycentric weights ``(3,)``, position ``(3,)`` m."""

    face: int
    bary: np.ndarray
    position: np.ndarray

    def vertices(self, part: BodyPart) -> np.ndarray:
        return part.faces[self.face]


def closest_point(part: BodyPart, point, tolerance: float = 0.01) -> SurfacePoint:
    """The surface point nearest ``point`` ``(3,)`` (m); an error if it is farther than
    ``tolerance`` (m) from the part.
    """
    q = np.asarray(point, dtype=float)
    if q.shape != (3,) or not np.isfinite(q).all():
        raise ValueError(f"point must be 3 finite coordinates (m), got {np.asarray(point)}")
    tri = part.vertices[part.faces]
    cand, bary = _closest_on_triangles(q, tri)
    d = np.linalg.norm(cand - q, axis=1)
    f = int(d.argmin())
    if d[f] > tolerance:
        raise ValueError(
            f"point {q.round(4).tolist()} is {d[f] * 1e3:.1f} mm off part "
            f"{part.name!r} (tolerance {tolerance * 1e3:g} mm)"
        )
    return SurfacePoint(f, bary[f], cand[f])


def point_at_uv(part: BodyPart, uv) -> SurfacePoint:
    """The surface point at chart coordinates ``uv`` ``(2,)``; an error off the chart."""
    p = np.asarray(uv, dtype=float)
    if p.shape != (2,) or not np.isfinite(p).all():
        raise ValueError(f"uv must be 2 finite chart coordinates, got {np.asarray(uv)}")
    t = part.uv[part.face_uv]
    lam = _bary2d(p, t)
    inside = (lam >= -1e-9).all(axis=1)
    if not inside.any():
        raise ValueError(f"uv {p.round(4).tolist()} is off the chart of part {part.name!r}")
    f = int(np.nonzero(inside)[0][0])
    w = np.clip(lam[f], 0, None)
    w = w / w.sum()
    return SurfacePoint(f, w, w @ part.vertices[part.faces[f]])


def vertex_point(part: BodyPart, vertex: int) -> SurfacePoint:
    """The surface point at a vertex."""
    if not 0 <= int(vertex) < part.n_vertices:
        raise ValueError(f"vertex {vertex} is not in part {part.name!r} (0..{part.n_vertices - 1})")
    f = int(np.nonzero((part.faces == vertex).any(1))[0][0])
    bary = (part.faces[f] == vertex).astype(float)
    return SurfacePoint(f, bary, part.vertices[int(vertex)].copy())


def geodesic_distance(part: BodyPart, source: SurfacePoint, local: float = 0.05) -> np.ndarray:
    """``(N,)`` geodesic distance (m) from ``source`` to every vertex.

    Far away: the heat method. Within ``local`` (m) of the source, where the heat method's
    smoothing error (about one edge length) would matter for loads, the chord ``c`` corrected by
    the angle ``theta`` between the two normals, ``s = c theta / (2 sin(theta / 2))`` (exact on
    circles and cylinders); the two are blended over the last fifth of ``local``.
    """
    heat = heat_distance(part, source)
    if local <= 0:
        return heat
    f = part.faces[source.face]
    n0 = source.bary @ part.normals[f]
    n0 /= np.linalg.norm(n0)
    chord = np.linalg.norm(part.vertices - source.position, axis=1)
    theta = np.arccos(np.clip(part.normals @ n0, -1.0, 1.0))
    arc = chord * np.where(theta > 1e-6, theta / (2 * np.sin(np.maximum(theta, 1e-6) / 2)), 1.0)
    w = np.clip((heat - 0.8 * local) / (0.2 * local), 0.0, 1.0)
    return (1 - w) * arc + w * heat


def heat_distance(part: BodyPart, source: SurfacePoint) -> np.ndarray:
    """``(N,)`` geodesic distance (m) from ``source`` by the heat method alone."""
    op = _operators(part)
    delta = np.zeros(part.n_vertices)
    delta[part.faces[source.face]] = source.bary
    u = op.heat(delta)
    v = part.vertices[part.faces]
    e = [v[:, 2] - v[:, 1], v[:, 0] - v[:, 2], v[:, 1] - v[:, 0]]  # edge opposite corner k
    n = np.cross(e[2], -e[1])
    area2 = np.linalg.norm(n, axis=1, keepdims=True)
    nhat = n / area2
    grad = sum(u[part.faces[:, k], None] * np.cross(nhat, e[k]) for k in range(3)) / area2
    x = -grad / np.maximum(np.linalg.norm(grad, axis=1, keepdims=True), 1e-300)
    div = np.zeros(part.n_vertices)
    cot = op.cot  # (M, 3): cotangent of the angle at corner k
    for k in range(3):
        i, j, m = k, (k + 1) % 3, (k + 2) % 3
        # edges leaving corner i towards j and m; the angle opposite edge (i, j) sits at m
        eij, eim = v[:, j] - v[:, i], v[:, m] - v[:, i]
        contrib = 0.5 * (cot[:, m] * (eij * x).sum(1) + cot[:, j] * (eim * x).sum(1))
        np.add.at(div, part.faces[:, i], contrib)
    phi = op.poisson(-div)
    return phi - phi[part.faces[source.face]] @ source.bary


def tangent_frame(part: BodyPart, point: SurfacePoint) -> np.ndarray:
    """``(3, 3)`` rows: t1 (the chart's ``u`` direction on the surface), t2, outward normal."""
    f = part.faces[point.face]
    n = point.bary @ part.normals[f]
    n /= np.linalg.norm(n)
    x, t = part.vertices[f], part.uv[part.face_uv[point.face]]
    jac = np.linalg.lstsq(
        np.stack([t[1] - t[0], t[2] - t[0]]), np.stack([x[1] - x[0], x[2] - x[0]]), rcond=None
    )[0]  # rows: dX/du, dX/dv
    t1 = jac[0] - (jac[0] @ n) * n
    t1 /= np.linalg.norm(t1)
    return np.stack([t1, np.cross(n, t1), n])


def log_map(part: BodyPart, source: SurfacePoint, distance: np.ndarray) -> np.ndarray:
    """``(N, 2)`` approximate geodesic polar coordinates of every vertex in the tangent frame at
    ``source``: geodesic distance along the direction of the offset projected on the plane.
    """
    frame = tangent_frame(part, source)
    d = part.vertices - source.position
    xy = np.stack([d @ frame[0], d @ frame[1]], 1)
    norm = np.linalg.norm(xy, axis=1, keepdims=True)
    return np.where(norm > 1e-12, xy / np.maximum(norm, 1e-12), 0.0) * distance[:, None]


# --- operators --------------------------------------------------------------------------------
@dataclass
class _Operators:
    cot: np.ndarray
    heat: callable
    poisson: callable


_OPS: "weakref.WeakKeyDictionary[BodyPart, _Operators]" = weakref.WeakKeyDictionary()


def _operators(part: BodyPart) -> _Operators:
    op = _OPS.get(part)
    if op is None:
        v, f = part.vertices, part.faces
        cot = np.zeros(f.shape)
        for k in range(3):
            a, b = v[f[:, (k + 1) % 3]] - v[f[:, k]], v[f[:, (k + 2) % 3]] - v[f[:, k]]
            cot[:, k] = (a * b).sum(1) / np.maximum(np.linalg.norm(np.cross(a, b), axis=1), 1e-300)
        rows, cols, vals = [], [], []
        for k in range(3):  # the edge opposite corner k joins the other two corners
            i, j = f[:, (k + 1) % 3], f[:, (k + 2) % 3]
            w = 0.5 * cot[:, k]
            rows += [i, j, i, j]
            cols += [j, i, i, j]
            vals += [-w, -w, w, w]
        n = part.n_vertices
        lap = sp.coo_matrix(
            (np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))), shape=(n, n)
        ).tocsc()
        mass = sp.diags(part.vertex_areas)
        h = np.linalg.norm(v[part.edges[:, 0]] - v[part.edges[:, 1]], axis=1).mean()
        heat = factorized((mass + h**2 * lap).tocsc())
        poisson = factorized(
            (lap + 1e-10 * mass * lap.diagonal().mean() / part.vertex_areas.mean()).tocsc()
        )
        op = _OPS[part] = _Operators(cot, heat, poisson)
    return op


def _closest_on_triangles(q: np.ndarray, tri: np.ndarray):
    """Closest point to ``q`` on each triangle ``(M, 3, 3)``: points ``(M, 3)``, bary ``(M, 3)``."""
    a, b, c = tri[:, 0], tri[:, 1], tri[:, 2]
    n = np.cross(b - a, c - a)
    n /= np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-300)
    p = q - ((q - a) * n).sum(1, keepdims=True) * n
    lam = _bary3d(p, a, b, c)
    best = np.where((lam >= 0).all(1, keepdims=True), p, np.nan)
    best_lam = np.where((lam >= 0).all(1, keepdims=True), lam, np.nan)
    for i, j in ((0, 1), (1, 2), (2, 0)):
        s, e = tri[:, i], tri[:, j]
        t = np.clip(((q - s) * (e - s)).sum(1) / np.maximum(((e - s) ** 2).sum(1), 1e-300), 0, 1)
        pt = s + t[:, None] * (e - s)
        cur = np.linalg.norm(best - q, axis=1)
        better = ~(cur <= np.linalg.norm(pt - q, axis=1))
        w = np.zeros_like(lam)
        w[:, i], w[:, j] = 1 - t, t
        best[better], best_lam[better] = pt[better], w[better]
    return best, best_lam


def _bary3d(p, a, b, c):
    v0, v1, v2 = b - a, c - a, p - a
    d00, d01, d11 = (v0 * v0).sum(1), (v0 * v1).sum(1), (v1 * v1).sum(1)
    d20, d21 = (v2 * v0).sum(1), (v2 * v1).sum(1)
    den = np.maximum(d00 * d11 - d01 * d01, 1e-300)
    l1 = (d11 * d20 - d01 * d21) / den
    l2 = (d00 * d21 - d01 * d20) / den
    return np.stack([1 - l1 - l2, l1, l2], 1)


def _bary2d(p, t):
    a, b, c = t[:, 0], t[:, 1], t[:, 2]
    det = (b[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (c[:, 0] - a[:, 0]) * (b[:, 1] - a[:, 1])
    det = np.where(np.abs(det) < 1e-300, 1e-300, det)
    l1 = ((p[0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (c[:, 0] - a[:, 0]) * (p[1] - a[:, 1])) / det
    l2 = ((b[:, 0] - a[:, 0]) * (p[1] - a[:, 1]) - (p[0] - a[:, 0]) * (b[:, 1] - a[:, 1])) / det
    return np.stack([1 - l1 - l2, l1, l2], 1)
