"""Rigid objects for the FEM's contact: each a signed distance ``phi`` (m; positive outside)
with its gradient (the object's outward normal), placed by a pose and pushed by a depth.

:class:`Sphere` (a fingertip, Hertz's indenter), :class:`Punch` (a flat-ended cylinder, a disk
pressed face-on) and :class:`Box` have exact distances. :class:`Surface` is any triangle mesh
(a user's object, anny's hand): the distance to its nearest triangle, signed by the normals
interpolated over that triangle, less a small ``rounding`` that makes the object's surface
smooth (its edges and corners rounded by that radius), so that Newton's steps see a normal that
turns continuously. A surface may also close along a per-vertex ``path`` (a hand's grip), where
the rigid shapes move along one direction. Lengths in m.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass, field, replace

import numpy as np
from scipy.spatial import cKDTree

from stmpl.geometry import closest_points


def unit(v) -> np.ndarray:
    v = np.asarray(v, dtype=float)
    n = np.linalg.norm(v)
    if v.shape != (3,) or not np.isfinite(n) or n == 0:
        raise ValueError(f"a direction must be a finite nonzero 3-vector, got {v.tolist()}")
    return v / n


def point(v, what: str) -> np.ndarray:
    v = np.asarray(v, dtype=float)
    if v.shape != (3,) or not np.all(np.isfinite(v)):
        raise ValueError(f"{what} must be a finite 3-vector (m), got {np.asarray(v).tolist()}")
    return v


def positive(value, what: str) -> float:
    if not (np.isfinite(value) and value > 0):
        raise ValueError(f"{what} must be > 0, got {value!r}")
    return float(value)


class Centred:
    """A rigid shape placed by its ``centre`` ``(3,)`` (m): pushed or moved, the same shape
    with its centre moved.
    """

    def pushed(self, depth: float, direction: np.ndarray):
        """The same shape ``depth`` (m) along ``direction`` ``(3,)``."""
        return self.moved(depth * direction)

    def moved(self, offset: np.ndarray):
        """The same shape moved by ``offset`` ``(3,)`` (m)."""
        return replace(self, centre=self.centre + offset)


@dataclass(frozen=True)
class Sphere(Centred):
    """A rigid ball of ``radius`` (m) centred at ``centre`` ``(3,)`` (m)."""

    centre: np.ndarray
    radius: float
    name = "sphere"

    def __post_init__(self) -> None:
        object.__setattr__(self, "centre", point(self.centre, "centre"))
        positive(self.radius, "radius")

    def distance(self, x: np.ndarray):
        """``(phi (K,), grad (K, 3), curvature (K, 3, 3))`` at points ``x`` ``(K, 3)``."""
        d = x - self.centre
        r = np.maximum(np.linalg.norm(d, axis=1), 1e-12)
        n = d / r[:, None]
        curv = (np.eye(3)[None] - n[:, :, None] * n[:, None, :]) / r[:, None, None]
        return r - self.radius, n, curv


@dataclass(frozen=True)
class Punch(Centred):
    """A rigid flat-ended cylinder of ``radius`` (m): its flat face a disk centred at
    ``centre`` ``(3,)`` facing along ``axis`` ``(3,)`` (the way it presses), its body behind
    the face. ``rounding`` (m, below ``radius``) rounds the rim of the face to that radius, as
    a real disk's edge is (0: the sharp-edged punch of the closed forms, whose rim concentrates
    the stress without bound).
    """

    centre: np.ndarray
    axis: np.ndarray
    radius: float
    rounding: float = 0.0
    name = "punch"

    def __post_init__(self) -> None:
        object.__setattr__(self, "centre", point(self.centre, "centre"))
        object.__setattr__(self, "axis", unit(self.axis))
        positive(self.radius, "radius")
        r = self.rounding
        if not (np.isfinite(r) and 0 <= r < self.radius):
            raise ValueError(
                f"rounding must be >= 0 and below the radius {self.radius:g} m, got {r!r}"
            )

    def distance(self, x: np.ndarray):
        """``(phi (K,), grad (K, 3), None)``: the exact signed distance to the semi-infinite
        cylinder with its rim rounded and its gradient (no curvature term is kept).

        The rounded punch is the sharp one of radius ``radius - rounding``, its face moved
        back by ``rounding``, grown by ``rounding`` in every direction.
        """
        r = self.rounding
        d = x - (self.centre - r * self.axis)
        y = d @ self.axis  # ahead of the (inner) face: y > 0
        radial = d - y[:, None] * self.axis
        rho = np.linalg.norm(radial, axis=1)
        e = radial / np.maximum(rho, 1e-12)[:, None]
        s = rho - (self.radius - r)
        phi = np.empty(len(x))
        grad = np.empty((len(x), 3))
        inside = (y <= 0) & (s <= 0)
        face = inside & (y >= s)
        phi[face], grad[face] = y[face], self.axis
        side = inside & ~face
        phi[side], grad[side] = s[side], e[side]
        out = ~inside
        yp, sp_ = np.maximum(y[out], 0.0), np.maximum(s[out], 0.0)
        phi[out] = np.hypot(yp, sp_)
        g = yp[:, None] * self.axis + sp_[:, None] * e[out]
        grad[out] = g / np.maximum(phi[out], 1e-300)[:, None]
        return phi - r, grad, None


@dataclass(frozen=True)
class Box(Centred):
    """A rigid box of ``half`` extents ``(3,)`` (m) about ``centre`` ``(3,)``, its axes the
    columns of ``rotation`` ``(3, 3)``.
    """

    centre: np.ndarray
    half: np.ndarray
    rotation: np.ndarray = field(default_factory=lambda: np.eye(3))
    name = "box"

    def __post_init__(self) -> None:
        object.__setattr__(self, "centre", point(self.centre, "centre"))
        half = np.asarray(self.half, dtype=float)
        if half.shape != (3,) or not np.all(np.isfinite(half)) or half.min() <= 0:
            raise ValueError(f"half extents must be three positive lengths (m), got {half}")
        object.__setattr__(self, "half", half)
        R = np.asarray(self.rotation, dtype=float)
        if R.shape != (3, 3) or not np.allclose(R.T @ R, np.eye(3), atol=1e-9):
            raise ValueError("rotation must be a 3 x 3 orthonormal matrix")
        object.__setattr__(self, "rotation", R)

    def distance(self, x: np.ndarray):
        """``(phi (K,), grad (K, 3), None)``: the box's exact signed distance."""
        p = (x - self.centre) @ self.rotation  # box coordinates
        q = np.abs(p) - self.half
        out = np.maximum(q, 0.0)
        dist_out = np.linalg.norm(out, axis=1)
        inside = dist_out == 0
        k = np.argmax(q, axis=1)
        phi = np.where(inside, q.max(1), dist_out)
        g = np.where(inside[:, None], 0.0, out / np.maximum(dist_out, 1e-300)[:, None])
        rows = np.flatnonzero(inside)
        g[rows, k[rows]] = 1.0
        g *= np.sign(p) + (p == 0)
        return phi, g @ self.rotation.T, None


PRESSES = ("press_disk", "press_sphere", "press_grip")
"""A dataset's placement kinds that press a rigid object into the tissue: a flat disk (its rim
rounded by ``rounding``, m) face-on, and a ball (a fingertip), each of ``radius`` (m) at vertex
``at`` of the part, pushed along the inward normal there; and anny's right hand closing in a
``grip`` round the limb at ``along`` and ``around`` (:func:`fem.objects.closing`)."""

ROUNDING = 5e-4
"""m: the default rounding of a :class:`Surface` (its faces offset outward by half a mm)."""

BAND = 0.002
"""m: how far from a :class:`Surface` its distance is exact; farther points (which no contact
pressure reaches: a press moves at most a millimetre a step) get this distance."""

NEAREST = 8
"""How many triangles, by their centroids, a point's nearest is first sought among; a point
they do not settle is checked against every triangle within reach."""


def clearance(shape, direction, points: np.ndarray, tolerance: float = 1e-6) -> float:
    """How far (m) ``shape`` must move back against ``direction`` ``(3,)`` (the way it presses;
    ``None`` for a :class:`Surface` closing along its path: back along the path) for none of
    ``points`` ``(K, 3)`` (m; the skin around where it presses) to lie inside it: 0 if none
    does. Found by bisection to ``tolerance`` (m).
    """
    d = None if direction is None else unit(direction)
    x = np.asarray(points, dtype=float).reshape(-1, 3)

    def inside(back: float) -> bool:
        at = shape.pushed(-back, None) if d is None else shape.moved(-back * d)
        return bool(at.distance(x)[0].min() < 0.0)

    if len(x) == 0 or not inside(0.0):
        return 0.0
    # doubled until clear, at most the points' own extent and 5 cm more (an object may reach
    # between the vertices of a coarse skin deeper than the skin's own relief)
    far = float(np.ptp(x, axis=0).max() if d is None else np.ptp(x @ d)) + 0.05
    lo, hi = 0.0, 0.001
    while inside(hi):
        if hi >= far:
            raise ValueError("the points lie inside the shape however far it moves back")
        lo, hi = hi, min(2 * hi, far)
    while hi - lo > tolerance:
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if inside(mid) else (lo, mid)
    return hi


def touching(shape, direction: np.ndarray, points: np.ndarray, tolerance: float = 1e-6):
    """``shape`` moved back against ``direction`` by its :func:`clearance` from ``points``:
    placed at first contact, from where a press's depth counts. A flat punch set on a vertex in
    a hollow of the skin would otherwise start pressed into the skin around that vertex, and
    carry a force at depth 0. The shape itself if nothing lies inside it.
    """
    back = clearance(shape, direction, points, tolerance)
    return shape if back == 0.0 else shape.moved(-back * unit(direction))


def skin_near(part, p: np.ndarray, radius: float, k: int = 8) -> np.ndarray:
    """``(K, 3)`` points of a body part's skin within ``radius`` (m) of ``p`` ``(3,)``: its
    (flat) faces sampled on a barycentric grid of ``k`` steps, where the FEM's refined skin puts
    its nodes (the points :func:`touching` keeps clear of).
    """
    x = skin_points(part, np.arange(len(part.faces)), k)
    return x[np.linalg.norm(x - p, axis=1) < radius]


def skin_points(part, faces: np.ndarray, k: int = 8) -> np.ndarray:
    """``(K, 3)`` points of a body part's ``faces`` (indices), each sampled on a barycentric grid
    of ``k`` steps.
    """
    i, j = np.meshgrid(np.arange(k + 1), np.arange(k + 1))
    keep = i + j <= k
    w = np.column_stack([i[keep], j[keep], k - i[keep] - j[keep]]) / k  # (P, 3)
    return np.einsum("pc,fcd->fpd", w, part.vertices[part.faces[faces]]).reshape(-1, 3)


@dataclass(frozen=True, eq=False)
class Surface:
    """A rigid triangle mesh: ``vertices`` ``(V, 3)`` (m, body coordinates) and ``faces``
    ``(F, 3)`` with outward normals, its faces offset outward by ``rounding`` (m). ``path``
    ``(V, 3)``, optional: how far each vertex moves per metre of depth (the mesh then closes by
    :meth:`pushed` along it, as a hand grips, instead of moving along one direction). The mesh
    need not be closed where nothing presses (a hand cut at the wrist).
    """

    vertices: np.ndarray
    faces: np.ndarray
    rounding: float = ROUNDING
    path: np.ndarray | None = None
    name: str = "mesh"

    def __post_init__(self) -> None:
        v = np.asarray(self.vertices, dtype=float)
        f = np.asarray(self.faces)
        if v.ndim != 2 or v.shape[1] != 3 or len(v) < 3 or not np.all(np.isfinite(v)):
            raise ValueError(f"{self.name}: vertices must be a finite (V >= 3, 3) array (m)")
        if f.ndim != 2 or f.shape[1] != 3 or len(f) == 0 or f.dtype.kind not in "iu":
            raise ValueError(f"{self.name}: faces must be a non-empty (F, 3) integer array")
        if f.min() < 0 or f.max() >= len(v):
            raise ValueError(f"{self.name}: faces index vertices outside 0..{len(v) - 1}")
        if not (np.isfinite(self.rounding) and self.rounding >= 0):
            raise ValueError(f"{self.name}: rounding must be a length >= 0 m, got {self.rounding}")
        tri = v[f]
        n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
        if not np.linalg.norm(n, axis=1).sum() > 0:
            raise ValueError(f"{self.name}: the mesh is degenerate (no surface area)")
        if self.path is not None:
            p = np.asarray(self.path, dtype=float)
            if p.shape != v.shape or not np.all(np.isfinite(p)):
                raise ValueError(f"{self.name}: path must be a finite {v.shape} array (m per m)")
            object.__setattr__(self, "path", p)
        object.__setattr__(self, "vertices", v)
        object.__setattr__(self, "faces", f.astype(np.int64))
        # angle-weighted vertex normals: the sign of a point off an edge or a corner
        unit_n = n / np.maximum(np.linalg.norm(n, axis=1), 1e-300)[:, None]
        vn = np.zeros_like(v)
        for k in range(3):
            a = tri[:, (k + 1) % 3] - tri[:, k]
            b = tri[:, (k + 2) % 3] - tri[:, k]
            cos = np.einsum("ij,ij->i", a, b) / np.maximum(
                np.linalg.norm(a, axis=1) * np.linalg.norm(b, axis=1), 1e-300
            )
            np.add.at(vn, f[:, k], np.arccos(np.clip(cos, -1, 1))[:, None] * unit_n)
        vn /= np.maximum(np.linalg.norm(vn, axis=1), 1e-300)[:, None]
        centroid = tri.mean(1)
        reach = float(np.linalg.norm(tri - centroid[:, None], axis=2).max())
        object.__setattr__(self, "_index", (tri, vn, cKDTree(centroid), reach, unit_n))

    def moved(self, offset: np.ndarray) -> "Surface":
        """The same mesh moved by ``offset`` ``(3,)`` (m)."""
        return replace(self, vertices=self.vertices + offset)

    def pushed(self, depth: float, direction: np.ndarray | None) -> "Surface":
        """The mesh ``depth`` (m) along ``direction`` ``(3,)``, or, for a mesh with a
        :attr:`path` (``direction`` ``None``), closed ``depth`` along it.
        """
        if self.path is None:
            if direction is None:
                raise ValueError(f"{self.name}: a mesh without a path needs a direction")
            return self.moved(depth * direction)
        if direction is not None:
            raise ValueError(f"{self.name}: a mesh with a path closes along it, not a direction")
        return replace(self, vertices=self.vertices + depth * self.path)

    def distance(self, x: np.ndarray):
        """``(phi (K,), grad (K, 3), None)`` at points ``x`` ``(K, 3)``: exact within
        :data:`BAND` of the mesh; farther points get :data:`BAND` or more outside (a bound:
        :data:`BAND` itself, or the distance to a nearby triangle), inside ``-BAND`` or their
        exact distance.
        """
        _, vn, tree, reach, normal = self._index
        # the nearest point lies no farther than the nearest centroid (d <= d0), and its
        # triangle's centroid within d + reach: points with no centroid within the band and
        # reach are far
        d0, nearest = tree.query(x, distance_upper_bound=BAND + self.rounding + reach)
        near = np.isfinite(d0)
        far = np.flatnonzero(~near)
        if len(far):  # a far point's nearest centroid, found to within twice its distance
            nearest[far] = tree.query(x[far], eps=1.0)[1]  # (an exact search costs ten times)
        # far points: BAND, signed by the nearest face's side (no pressure reaches them);
        # where that says inside, by the nearest centroid's itself (pressure would)
        grad = x - tree.data[nearest]
        inside = np.einsum("ki,ki->k", grad, normal[nearest]) < 0
        recheck = far[inside[far]]
        if len(recheck):
            nearest[recheck] = tree.query(x[recheck])[1]
            grad[recheck] = x[recheck] - tree.data[nearest[recheck]]
            inside[recheck] = np.einsum("ki,ki->k", grad[recheck], normal[nearest[recheck]]) < 0
        phi = np.where(inside, -BAND, BAND)
        grad /= np.maximum(np.linalg.norm(grad, axis=1), 1e-300)[:, None]
        near = np.flatnonzero(near)
        if len(near) == 0:
            return phi, grad, None
        xq = x[near]
        # a point the nearest triangles already put outside, farther than the band, needs no
        # exact distance: only the triangles that could bring it within the band are searched
        # (on a hand of 50,000 faces, most of the skin's points are such)
        face, dist, c, bary = self.closest(xq, BAND + self.rounding)
        at = np.einsum("kj,kji->ki", bary, vn[self.faces[face]])
        side = np.sign(np.einsum("ki,ki->k", xq - c, at))
        side[side == 0] = 1.0
        g = (xq - c) * (side / np.maximum(dist, 1e-300))[:, None]
        flat = dist < 1e-12
        g[flat] = at[flat] / np.maximum(np.linalg.norm(at[flat], axis=1), 1e-300)[:, None]
        phi[near] = side * dist - self.rounding
        grad[near] = g
        return phi, grad, None

    def path_at(self, x: np.ndarray, band: float | None = None) -> np.ndarray:
        """``(K, 3)``: the :attr:`path` (m per m of depth) at the point of the mesh nearest to
        each of ``x`` ``(K, 3)`` (m), interpolated over its triangle. ``band`` (m): a point
        outside the mesh farther than it takes the path at a point of the mesh near it (among
        its nearest triangles), not searched for the nearest (:meth:`closest`).
        """
        if self.path is None:
            raise ValueError(f"{self.name}: the mesh has no path")
        x = np.asarray(x, dtype=float).reshape(-1, 3)
        face, _, _, bary = self.closest(x, band)
        return np.einsum("kj,kji->ki", bary, self.path[self.faces[face]])

    def closest(self, x: np.ndarray, band: float | None = None):
        """``(face (K,), distance (K,) m, point (K, 3), barycentric (K, 3))``: the point of the
        mesh nearest to each of ``x`` ``(K, 3)``, exactly: among the triangles of the
        :data:`NEAREST` nearest centroids, and where those do not settle it, among every
        triangle within reach. ``band`` (m): a point those triangles put outside the mesh
        farther than it needs no exact answer: only triangles that could bring it within
        ``band`` are searched, and where none does, the first answer (no nearer than the
        truth) stays.
        """
        tri, vn, tree, reach, _ = self._index
        k = min(NEAREST, len(tri))
        dk, ik = tree.query(x, k=k)
        dk, ik = dk.reshape(len(x), k), ik.reshape(len(x), k)
        c, bary = closest_points(tri[ik.ravel()], np.repeat(x, k, axis=0))
        dist = np.linalg.norm(np.repeat(x, k, axis=0) - c, axis=1).reshape(len(x), k)
        j = np.argmin(dist, axis=1)
        rows = np.arange(len(x))
        face, dist = ik[rows, j], dist[rows, j]
        c, bary = c.reshape(len(x), k, 3)[rows, j], bary.reshape(len(x), k, 3)[rows, j]
        sought = dist
        if band is not None:  # outside beyond the band: sought only within it
            at = np.einsum("kj,kji->ki", bary, vn[self.faces[face]])
            out = (np.einsum("ki,ki->k", x - c, at) > 0) & (dist > band)
            sought = np.where(out, band, dist)
        # a point whose k nearest centroids do not settle it: every triangle in reach
        unsure = np.flatnonzero(dk[:, -1] < sought + reach) if k < len(tri) else []
        if len(unsure):
            lists = tree.query_ball_point(x[unsure], sought[unsure] + reach + 1e-12)
            counts = np.fromiter(map(len, lists), int, len(lists))
            point = np.repeat(np.arange(len(unsure)), counts)
            cand = np.fromiter(itertools.chain.from_iterable(lists), int, int(counts.sum()))
            cc, cb = closest_points(tri[cand], x[unsure][point])
            cd = np.linalg.norm(x[unsure][point] - cc, axis=1)
            order = np.lexsort((cd, point))
            first = order[np.r_[0, np.flatnonzero(np.diff(point[order])) + 1]]
            # (every unsure point has candidates: its k-th centroid lies within the ball)
            first = first[cd[first] <= dist[unsure[point[first]]]]  # no farther than the first
            at = unsure[point[first]]
            face[at], dist[at] = cand[first], cd[first]
            c[at], bary[at] = cc[first], cb[first]
        return face, dist, c, bary
