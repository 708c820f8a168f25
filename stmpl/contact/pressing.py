"""Contact from object meshes: which skin vertices an object pressed on a body part touches, and
the force it puts on each.

An :class:`Pressing` is a mesh (m, in its own frame), a pose (4x4, into the part's body
coordinates) and a total force (N). :func:`contact` finds, for each object, the part's vertices
inside it or within ``tolerance`` of its surface, and splits its force over them along the inward
normals, the paper's way: ``F_i = F_total / |V|`` (``split="equal"``), or in proportion to each
vertex's area (``"area"``) or to its penetration depth plus the tolerance (``"depth"``). Several
objects add up. The :class:`Contact` keeps what it found (objects, poses, touched vertices,
penetration per vertex, area, mean pressure) and gives the :class:`~stmpl.loads.Load` a scene
takes (its ``source`` is the contact, so a picture can draw the objects).

Inside is where the object's generalized winding number exceeds 1/2 (Jacobson et al. 2013): exact
for a closed (watertight) mesh, and robust to small holes such as a hand cut off at the wrist. A
mesh that is not watertight is used that way and says so (``Contact.open_objects``); one with no
faces, no area or non-finite vertices is refused.
"""

from __future__ import annotations

import hashlib
import itertools
import pathlib
from dataclasses import dataclass, field

import numpy as np
from scipy.spatial import cKDTree

from stmpl.geometry import closest_points
from stmpl.loads import Load, _check_force, _check_total
from stmpl.mesh import Mesh
from stmpl.part import BodyPart

SPLITS = ("equal", "area", "depth")
MESH_FILES = (".obj", ".ply", ".stl", ".glb", ".gltf", ".off")


def pose_matrix(position=(0.0, 0.0, 0.0), rotation=None) -> np.ndarray:
    """A ``(4, 4)`` pose from a ``position`` (m) and a ``rotation``: a ``(3, 3)`` matrix or a
    rotation vector ``(3,)`` (axis times angle, rad); ``None`` for none.
    """
    t = np.asarray(position, dtype=float)
    if t.shape != (3,) or not np.all(np.isfinite(t)):
        raise ValueError(f"position must be 3 finite numbers (m), got {position!r}")
    if rotation is None:
        R = np.eye(3)
    else:
        r = np.asarray(rotation, dtype=float)
        if not np.all(np.isfinite(r)):
            raise ValueError(f"rotation is not finite: {rotation!r}")
        if r.shape == (3,):
            angle = float(np.linalg.norm(r))
            R = np.eye(3) if angle == 0 else rotation_matrix(r, angle)
        elif r.shape == (3, 3):
            R = r
        else:
            raise ValueError(
                f"rotation must be a (3, 3) matrix or a rotation vector (3,), got shape {r.shape}"
            )
    out = np.eye(4)
    out[:3, :3], out[:3, 3] = R, t
    return check_pose(out)


def rotation_matrix(axis, angle: float) -> np.ndarray:
    """``(3, 3)`` rotation by ``angle`` rad about ``axis`` (Rodrigues)."""
    axis = np.asarray(axis, dtype=float) / np.linalg.norm(axis)
    K = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    return np.eye(3) + np.sin(angle) * K + (1 - np.cos(angle)) * K @ K


def check_pose(pose) -> np.ndarray:
    """``pose`` as a ``(4, 4)`` rigid transform (rotation and translation, last row 0 0 0 1);
    ``ValueError`` naming what is wrong.
    """
    P = np.asarray(pose, dtype=float)
    if P.shape != (4, 4):
        raise ValueError(f"a pose is a (4, 4) matrix, got shape {P.shape}")
    if not np.all(np.isfinite(P)):
        raise ValueError("the pose is not finite (NaN or inf)")
    R = P[:3, :3]
    if (
        not np.allclose(P[3], [0, 0, 0, 1])
        or not np.allclose(R @ R.T, np.eye(3), atol=1e-6)
        or np.linalg.det(R) < 0
    ):
        raise ValueError("the pose is not a rigid transform (a rotation and a translation)")
    return P


def read_mesh(path):
    """A ``trimesh.Trimesh`` from an OBJ, PLY, STL, GLB/glTF or OFF file (a scene's meshes are
    joined); lengths as stored, which stmpl takes for metres.
    """
    import trimesh  # deferred: object meshes and closest points only

    path = pathlib.Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"mesh file not found: {path}")
    if path.suffix.lower() not in MESH_FILES:
        raise ValueError(f"{path.name}: not a mesh file stmpl reads ({', '.join(MESH_FILES)})")
    try:
        # read as stored first: processing would drop non-finite vertices and their faces
        mesh = trimesh.load(str(path), force="mesh", process=False)
    except Exception as e:  # noqa: BLE001 - trimesh raises many kinds for a broken file
        raise ValueError(f"{path} is not a readable mesh: {type(e).__name__}: {e}") from e
    if not isinstance(mesh, trimesh.Trimesh) or len(mesh.faces) == 0:
        raise ValueError(f"{path} holds no triangle mesh")
    bad = ~np.isfinite(mesh.vertices).all(axis=1)
    if bad.any():
        raise ValueError(
            f"{path}: {int(bad.sum())} of its {len(mesh.vertices)} vertices are not finite "
            f"(the first: vertex {int(np.flatnonzero(bad)[0])}); fix the file"
        )
    mesh.process()
    return mesh


@dataclass(frozen=True, eq=False)
class Pressing:
    """An object pressed on a part: ``mesh`` (a ``trimesh.Trimesh`` or :class:`stmpl.mesh.Mesh`,
    m, its own frame), ``pose`` ``(4, 4)`` into body coordinates, ``total`` force (N) and a
    ``name``.
    """

    mesh: object
    pose: np.ndarray = field(default_factory=lambda: np.eye(4))
    total: float = 1.0
    name: str = "object"

    def __post_init__(self) -> None:
        if not isinstance(self.mesh, Mesh):
            import trimesh  # deferred: object meshes and closest points only

            if not isinstance(self.mesh, trimesh.Trimesh):
                raise TypeError(
                    f"object {self.name!r}: mesh must be a trimesh.Trimesh or stmpl.mesh.Mesh, "
                    f"got {type(self.mesh).__name__}"
                )
        m = self.mesh
        if len(m.faces) == 0 or not np.all(np.isfinite(m.vertices)):
            raise ValueError(f"object {self.name!r}: the mesh has no faces or non-finite vertices")
        if not m.area > 0:
            raise ValueError(f"object {self.name!r}: the mesh is degenerate (no surface area)")
        object.__setattr__(self, "pose", check_pose(self.pose))
        object.__setattr__(self, "total", _check_total(self.total))

    def posed(self):
        """The mesh in body coordinates."""
        return self.mesh.copy().apply_transform(self.pose)


@dataclass(frozen=True, eq=False)
class Contact:
    """What :func:`contact` found. ``touched[k]``: vertex indices object ``k`` touches;
    ``penetration`` ``(N,)`` m, how deep each vertex lies inside an object (0 outside);
    ``force`` ``(N,)`` N per vertex along the inward normal; ``area`` m^2 of the touched
    vertices; ``open_objects``: names of objects whose mesh is not watertight.
    """

    part: BodyPart
    objects: tuple
    touched: tuple
    penetration: np.ndarray
    force: np.ndarray
    area: float
    split: str
    tolerance: float
    open_objects: tuple = ()

    @property
    def total(self) -> float:
        return float(sum(o.total for o in self.objects))

    @property
    def pressure(self) -> float:
        """Mean pressure over the touched area, Pa."""
        return self.total / self.area

    @property
    def vertices(self) -> np.ndarray:
        """Every touched vertex, sorted."""
        return np.unique(np.concatenate(self.touched))

    def summary(self) -> str:
        names = "; ".join(
            f"{o.name} {o.total:g} N on {len(t)} vertices"
            for o, t in zip(self.objects, self.touched)
        )
        total = f" ({self.total:g} N in all)" if len(self.objects) > 1 else ""
        return (
            f"contact: {names}{total}; {self.area * 1e4:.2f} cm^2, mean pressure "
            f"{self.pressure / 1e3:.2f} kPa, reaching {1e3 * self.penetration.max():.2f} mm "
            "into the skin at rest"
        )

    def load(self) -> Load:
        """The :class:`~stmpl.loads.Load` of this contact (kind ``contact``), for a scene."""
        params = {
            "split": self.split,
            "tolerance": self.tolerance,
            "objects": [
                {"name": o.name, "total": o.total, "vertices": int(len(t)), "pose": o.pose.tolist()}
                for o, t in zip(self.objects, self.touched)
            ],
        }
        return Load(
            "contact",
            params,
            self.vertices,
            self.total,
            self.force.copy(),
            self.area,
            part_id=self.part.fingerprint,
            source=self,
        )


def solid_angles(tri: np.ndarray, points: np.ndarray) -> np.ndarray:
    """``(P,)`` the signed solid angle (sr) of each triangle ``(P, 3, 3)`` seen from its point
    of ``points`` ``(P, 3)`` (Van Oosterom and Strackee's formula).
    """
    d = tri - points[:, None]
    a, b, c = d[:, 0], d[:, 1], d[:, 2]
    la, lb, lc = (np.linalg.norm(x, axis=-1) for x in (a, b, c))
    det = np.einsum("pi,pi->p", a, np.cross(b, c))
    den = (
        la * lb * lc
        + np.einsum("pi,pi->p", a, b) * lc
        + np.einsum("pi,pi->p", b, c) * la
        + np.einsum("pi,pi->p", c, a) * lb
    )
    return 2 * np.arctan2(det, den)


FAR = 3.0
"""A cluster of triangles seen from farther than this many times its radius counts as its
dipole (the first term of its far field: the solid angle's error under about 1 % of what the
cluster subtends)."""
LEAF = 48
"""Triangles per cluster of :func:`winding_number`."""


def clusters(tri: np.ndarray, leaf: int = LEAF) -> tuple[np.ndarray, np.ndarray]:
    """Triangles ``(M, 3, 3)`` split at the median of their centroids along the longest side
    of each box until a part holds at most ``leaf``, every part of a level at once: ``(order
    (M,), starts (K + 1,))``, the triangles part after part and where each part starts.
    """
    centroid = tri.mean(1)
    order, starts = np.arange(len(tri)), np.array([0, len(tri)])
    while True:
        sizes = np.diff(starts)
        split = sizes > leaf
        if not split.any():
            return order, starts
        part = np.repeat(np.arange(len(sizes)), sizes)
        c = centroid[order]
        axis = np.argmax(
            np.maximum.reduceat(c, starts[:-1]) - np.minimum.reduceat(c, starts[:-1]), 1
        )
        key = np.where(split[part], c[np.arange(len(c)), axis[part]], 0.0)
        order = order[np.lexsort((key, part))]  # stable: ties keep their order
        starts = np.sort(np.concatenate([starts, starts[:-1][split] + sizes[split] // 2]))


CACHED_CLUSTERINGS = 8
"""Meshes whose clusters :func:`winding_number` keeps, by their faces."""

_CLUSTERINGS: dict[bytes, tuple[np.ndarray, np.ndarray]] = {}


def _clusters_of(faces: np.ndarray, tri: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """:func:`clusters` of ``tri``, kept for the next mesh with the same ``faces``: a hand
    closing on the skin keeps its triangles as they move, and any split of them into clusters
    serves: each cluster's centre, radius and dipole are measured again at each call, so a
    cluster a finger's curl has stretched is only summed exactly from farther away. The split
    made at the first pose serves every later one.
    """
    key = hashlib.blake2b(np.ascontiguousarray(faces).tobytes(), digest_size=16).digest()
    if key not in _CLUSTERINGS:
        if len(_CLUSTERINGS) >= CACHED_CLUSTERINGS:
            _CLUSTERINGS.pop(next(iter(_CLUSTERINGS)))
        _CLUSTERINGS[key] = clusters(tri)
    return _CLUSTERINGS[key]


def _spans(starts: np.ndarray, which: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """For ranges ``starts[k] .. starts[k + 1]`` of each ``which`` ``(Q,)``: ``(owner, at)``,
    the position in ``which`` and the index of every element of every range, range by range.
    """
    n = starts[which + 1] - starts[which]
    owner = np.repeat(np.arange(len(which)), n)
    at = np.repeat(starts[which] - np.cumsum(n) + n, n) + np.arange(int(n.sum()))
    return owner, at


def winding_number(
    mesh, points: np.ndarray, far: float = FAR, chunk: int = 1_000_000
) -> np.ndarray:
    """``(P,)`` generalized winding number of a triangle mesh at ``points`` ``(P, 3)``: the sum
    of the signed solid angles of its triangles over ``4 pi`` (1 inside a closed outward-facing
    mesh, 0 outside). Triangles are grouped in clusters; a cluster seen from farther than
    ``far`` times its radius counts as its dipole, the others triangle by triangle (Barill et
    al. 2018, "Fast winding numbers for soups and clouds", to first order); a few points
    (at most ``chunk / 4`` point-triangle pairs) are summed over every triangle exactly instead.
    ``chunk``: at most about this many (point, cluster) pairs at a time.
    """
    tri = np.asarray(mesh.triangles, dtype=float)  # (M, 3, 3)
    points = np.asarray(points, dtype=float).reshape(-1, 3)
    if not len(points) or not len(tri):
        return np.zeros(len(points))
    if len(points) * len(tri) <= chunk // 4:  # a few points: every triangle exactly, at once
        rows = np.repeat(np.arange(len(points)), len(tri))
        angle = solid_angles(np.tile(tri, (len(points), 1, 1)), points[rows])
        return np.bincount(rows, angle, len(points)) / (4 * np.pi)
    order, starts = _clusters_of(np.asarray(mesh.faces), tri)
    tri = tri[order]  # cluster after cluster
    area = 0.5 * np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])  # (M, 3)
    size = np.linalg.norm(area, axis=1)
    first = starts[:-1]
    dipole = np.add.reduceat(area, first)  # (K, 3)
    weight = np.add.reduceat(size, first)
    moment = np.add.reduceat(size[:, None] * tri.mean(1), first)
    centre = moment / np.maximum(weight, 1e-300)[:, None]
    cluster = np.repeat(np.arange(len(first)), np.diff(starts))
    reach = np.linalg.norm(tri - centre[cluster][:, None], axis=2).max(1)
    radius = np.maximum.reduceat(reach, first)
    out = np.empty(len(points))
    step = max(1, chunk // len(first))  # points at a time: (step, K) pairs in memory
    for s in range(0, len(points), step):
        x = points[s : s + step]
        away = centre[None] - x[:, None]  # (p, K, 3)
        dist = np.linalg.norm(away, axis=2)
        near = dist <= far * radius[None]
        flux = np.einsum("pki,ki->pk", away, dipole)  # the dipoles' solid angles, times dist^3
        angle = np.divide(flux, dist**3, out=np.zeros_like(flux), where=~near).sum(1)
        pk = np.argwhere(near)
        if len(pk):
            pair, cols = _spans(starts, pk[:, 1])
            rows = pk[pair, 0]
            np.add.at(angle, rows, solid_angles(tri[cols], x[rows]))
        out[s : s + step] = angle / (4 * np.pi)
    return out


REACH_QUANTILES = (0.5, 0.9, 0.99)
""":func:`distance_to_surface` searches a mesh's triangles in groups by their reach (the
farthest corner from the centroid), split at these quantiles: a point's search reaches as far
as its group's largest triangle, so a few long ones (a hand's palm beside its fine fingertips)
do not widen every point's search."""


def distance_to_surface(mesh, points: np.ndarray, upto: float = np.inf) -> np.ndarray:
    """``(P,)`` distance (m) from each point to the mesh's surface: exact where it is at most
    ``upto``, and elsewhere a lower bound above ``upto`` (default: exact everywhere).

    A point's nearest triangle centroid, at ``d``, bounds its distance from above; a triangle
    whose centroid lies farther than ``min(d, upto) + r`` (``r`` its reach, the distance from
    its centroid to its farthest corner) holds no point within that. So only the triangles
    inside those balls are searched, exactly, the triangles grouped by reach
    (:data:`REACH_QUANTILES`) so that each group's ball is as small as its triangles allow.
    """
    points = np.asarray(points, dtype=float).reshape(-1, 3)
    vertices, faces = np.asarray(mesh.vertices), np.asarray(mesh.faces)
    tri = vertices[faces]
    centroid = tri.mean(1)
    reach = np.linalg.norm(tri - centroid[:, None], axis=2).max(1)
    edges = np.unique(np.quantile(reach, (*REACH_QUANTILES, 1.0)))
    group = np.searchsorted(edges, reach)  # each triangle's: reach <= edges[group]
    groups = [np.flatnonzero(group == g) for g in range(len(edges))]
    groups = [(f, cKDTree(centroid[f]), float(reach[f].max())) for f in groups if len(f)]
    nearest = np.min([tree.query(points)[0] for _, tree, _ in groups], axis=0)
    sought = np.minimum(nearest, upto)
    rows, cols = [], []
    for f, tree, r in groups:
        balls = tree.query_ball_point(points, sought + r)
        counts = np.fromiter(map(len, balls), np.int64, len(balls))
        rows.append(np.repeat(np.arange(len(points)), counts))
        ball = np.fromiter(itertools.chain.from_iterable(balls), np.int64, int(counts.sum()))
        cols.append(f[ball])
    rows, cols = np.concatenate(rows), np.concatenate(cols)
    q, _ = closest_points(tri[cols], points[rows])
    out = np.full(len(points), np.inf)
    np.minimum.at(out, rows, np.linalg.norm(q - points[rows], axis=1))
    # a point with no triangle within upto lies farther: just above it is a lower bound
    return np.minimum(out, np.nextafter(sought, np.inf))


def contact(part: BodyPart, objects, tolerance: float = 0.002, split: str = "equal") -> Contact:
    """The contact of ``objects`` (a :class:`Pressing` or several) with ``part``: touched
    vertices (inside an object or within ``tolerance`` m of its surface), penetration depths and
    the per-vertex force (``split``: ``equal``, ``area`` or ``depth``).
    """
    objs = (objects,) if isinstance(objects, Pressing) else tuple(objects)
    if not objs:
        raise ValueError("contact needs at least one object")
    for o in objs:
        if not isinstance(o, Pressing):
            raise TypeError(f"objects must be Pressing, got {type(o).__name__}")
    if not (np.isfinite(tolerance) and tolerance >= 0):
        raise ValueError(f"tolerance must be a finite length >= 0 m, got {tolerance!r}")
    if split not in SPLITS:
        raise ValueError(f"split must be one of {SPLITS}, got {split!r}")
    x = part.vertices
    n = part.n_vertices
    pen = np.zeros(n)
    force = np.zeros(n)
    touched, open_ = [], []
    for o in objs:
        mesh = o.posed()
        if not mesh.is_watertight:
            open_.append(o.name)
        box = np.linalg.norm(
            np.maximum(0, np.maximum(mesh.bounds[0] - x, x - mesh.bounds[1])), axis=1
        )  # 0 inside the object's bounding box
        cand = np.flatnonzero(box <= tolerance)
        inside = winding_number(mesh, x[cand]) > 0.5
        if len(cand) == n and inside.all():
            across = 1e3 * float(np.linalg.norm(mesh.extents))
            raise ValueError(
                f"object {o.name!r} ({across:.0f} mm across) encloses the whole of "
                f"{part.name!r}: nothing is left to press on (a mesh in millimetres? stmpl "
                "reads metres)"
            )
        dist = distance_to_surface(mesh, x[cand], upto=tolerance)
        dist[inside] = distance_to_surface(mesh, x[cand][inside])  # depths: exact
        hit = inside | (dist <= tolerance)
        if not hit.any():
            near = np.argsort(box)[:64]  # the closest lie among the box's closest
            gap = float(distance_to_surface(mesh, x[near]).min())
            raise ValueError(
                f"no contact: object {o.name!r} is {gap * 1e3:.1f} mm from the "
                f"skin of {part.name!r} at its closest (tolerance "
                f"{tolerance * 1e3:g} mm; move it or press deeper)"
            )
        idx = cand[hit]
        depth = np.where(inside, dist, 0.0)[hit]
        pen[idx] = np.maximum(pen[idx], depth)
        w = {
            "equal": np.ones(len(idx)),
            "area": part.vertex_areas[idx],
            "depth": depth + tolerance + 1e-12,
        }[split]
        force[idx] += o.total * w / w.sum()
        touched.append(idx)
    _check_force(force)
    every = np.unique(np.concatenate(touched))
    return Contact(
        part,
        objs,
        tuple(touched),
        pen,
        force,
        float(part.vertex_areas[every].sum()),
        split,
        float(tolerance),
        tuple(open_),
    )
