"""A body part: a triangulated patch of the skin with its own UV chart.

Everything downstream (tissue, loads, UV images, FEM, predictors) works on the vertices of a
:class:`BodyPart`. Points are rows, ``(N, 3)`` in metres; UVs are per corner, ``(T, 2)`` in the
part's own chart, normalised to ``[0, 1]^2`` with the aspect ratio kept and a margin left for the
pixels that UV images carry past the chart's edge.
"""

from __future__ import annotations

import dataclasses
import hashlib
from dataclasses import dataclass, field
from functools import cached_property

import numpy as np
import scipy.sparse as sp
from scipy.spatial import cKDTree

from stmpl.geometry import project_on_polyline, triangle_areas, vertex_normals

CHART_MARGIN = 0.04
"""Share of the unit square left free around a part's chart (room for padded pixels)."""


@dataclass(frozen=True, eq=False)
class BodyPart:
    """A skin patch of a body model, in its rest pose.

    Attributes:
        name: part name, e.g. ``"left_arm"``.
        vertices: ``(N, 3)`` rest positions, metres.
        faces: ``(M, 3)`` vertex indices, counter-clockwise seen from outside.
        normals: ``(N, 3)`` unit outward vertex normals (from the whole body, so rims are right).
        uv: ``(T, 2)`` corner UVs in the part's chart, ``[0, 1]^2``, aspect kept.
        face_uv: ``(M, 3)`` indices into ``uv`` for each face corner.
        uv_vertex: ``(T,)`` the vertex each UV corner belongs to.
        uv_scale: metres per chart unit (square root of 3D area over UV area).
        rims: open boundary loops, each an ordered ``(K,)`` array of vertex indices.
        axis: ``(K, 3)`` limb centre line from proximal to distal (metres), or ``None``.
        body_index: ``(N,)`` index of each vertex in the full body mesh.
        source: provenance: body model, its options, part name (JSON-serialisable).
        coarser: the part this one was subdivided from (:func:`subdivide`), else ``None``: its
            vertices are this one's first, and this one's others its edges' midpoints in the
            order of its :attr:`edges`.
    """

    name: str
    vertices: np.ndarray
    faces: np.ndarray
    normals: np.ndarray
    uv: np.ndarray
    face_uv: np.ndarray
    uv_vertex: np.ndarray
    uv_scale: float
    rims: tuple[np.ndarray, ...] = ()
    axis: np.ndarray | None = None
    body_index: np.ndarray | None = None
    source: dict = field(default_factory=dict)
    coarser: "BodyPart | None" = field(default=None, repr=False)

    def __post_init__(self) -> None:
        n = len(self.vertices)
        _check_shape("vertices", self.vertices, (None, 3))
        _check_shape("faces", self.faces, (None, 3))
        _check_shape("normals", self.normals, (n, 3))
        _check_shape("uv", self.uv, (None, 2))
        _check_shape("face_uv", self.face_uv, (len(self.faces), 3))
        _check_shape("uv_vertex", self.uv_vertex, (len(self.uv),))
        if self.faces.size and (self.faces.min() < 0 or self.faces.max() >= n):
            raise ValueError(
                f"BodyPart.faces index out of range [0, {n}): "
                f"min {self.faces.min()}, max {self.faces.max()}"
            )
        if not np.array_equal(self.uv_vertex[self.face_uv], self.faces):
            raise ValueError("BodyPart.face_uv does not match faces through uv_vertex")
        for name in ("vertices", "normals", "uv"):
            if not np.isfinite(getattr(self, name)).all():
                raise ValueError(f"BodyPart.{name} contains non-finite values")
        if self.axis is not None:
            _check_shape("axis", self.axis, (None, 3))

    # --- sizes -------------------------------------------------------------------------------
    @property
    def n_vertices(self) -> int:
        return len(self.vertices)

    @property
    def n_faces(self) -> int:
        return len(self.faces)

    # --- derived geometry (computed once) ------------------------------------------------------
    @cached_property
    def edges(self) -> np.ndarray:
        """``(E, 2)`` unique undirected vertex edges, sorted pairs."""
        e = np.concatenate([self.faces[:, [0, 1]], self.faces[:, [1, 2]], self.faces[:, [2, 0]]])
        return np.unique(np.sort(e, axis=1), axis=0)

    @cached_property
    def adjacency(self) -> sp.csr_matrix:
        """``(N, N)`` symmetric boolean vertex adjacency over :attr:`edges`."""
        e, n = self.edges, self.n_vertices
        a = sp.coo_matrix(
            (np.ones(2 * len(e), bool), (np.r_[e[:, 0], e[:, 1]], np.r_[e[:, 1], e[:, 0]])), (n, n)
        )
        return a.tocsr()

    @cached_property
    def tree(self):
        """A k-d tree of the rest positions (``scipy.spatial.cKDTree``), for neighbourhoods in
        metres.
        """
        return cKDTree(self.vertices)

    @cached_property
    def face_areas(self) -> np.ndarray:
        """``(M,)`` triangle areas, m^2."""
        return triangle_areas(self.vertices, self.faces)

    @cached_property
    def vertex_areas(self) -> np.ndarray:
        """``(N,)`` barycentric vertex areas (a third of each adjacent face), m^2."""
        a = np.zeros(self.n_vertices)
        np.add.at(a, self.faces.ravel(), np.repeat(self.face_areas / 3.0, 3))
        return a

    @cached_property
    def rim_distance(self) -> np.ndarray:
        """``(N,)`` straight-line distance (m) of each vertex from the nearest open-rim vertex
        (``inf`` everywhere for a part without rims).
        """
        if not self.rims:
            return np.full(self.n_vertices, np.inf)

        return cKDTree(self.vertices[np.concatenate(self.rims)]).query(self.vertices)[0]

    @cached_property
    def seam_groups(self) -> tuple[np.ndarray, ...]:
        """The UV copies of each seam vertex: one ``(k,)`` array of ``uv`` indices per vertex with
        ``k >= 2`` copies, ordered by vertex index.
        """
        order = np.argsort(self.uv_vertex, kind="stable")
        verts, starts, counts = np.unique(
            self.uv_vertex[order], return_index=True, return_counts=True
        )
        return tuple(order[s : s + c] for s, c in zip(starts, counts) if c > 1)

    @cached_property
    def seam_vertices(self) -> np.ndarray:
        """``(S,)`` vertices with more than one UV copy."""
        return np.array([self.uv_vertex[g[0]] for g in self.seam_groups], dtype=np.int64)

    @cached_property
    def axial(self) -> np.ndarray:
        """``(N,)`` arc length (m) of each vertex's projection on the limb axis."""
        if self.axis is None:
            raise ValueError(f"part {self.name!r} has no limb axis (not a limb)")
        return project_on_polyline(self.vertices, self.axis)

    def mesh(self, vertices: np.ndarray | None = None):
        """A ``trimesh.Trimesh`` of the part (optionally with other vertex positions)."""
        import trimesh  # deferred: object meshes and closest points only

        v = self.vertices if vertices is None else vertices
        return trimesh.Trimesh(v, self.faces, process=False)

    @cached_property
    def fingerprint(self) -> str:
        """16 hex digits identifying the mesh: the SHA-256 of the name, vertices and faces."""
        h = hashlib.sha256(self.name.encode())
        for a in (
            np.ascontiguousarray(self.vertices, np.float64),
            np.ascontiguousarray(self.faces, np.int64),
        ):
            h.update(a.tobytes())
        return h.hexdigest()[:16]

    def arrays(self) -> dict[str, np.ndarray]:
        """Arrays for saving (``np.savez``); inverse of :meth:`from_arrays`."""
        out = {
            k: getattr(self, k)
            for k in ("vertices", "faces", "normals", "uv", "face_uv", "uv_vertex")
        }
        out["uv_scale"] = np.array(self.uv_scale)
        out["rim_lengths"] = np.array([len(r) for r in self.rims], dtype=np.int64)
        out["rims"] = np.concatenate(self.rims) if self.rims else np.zeros(0, np.int64)
        if self.axis is not None:
            out["axis"] = self.axis
        if self.body_index is not None:
            out["body_index"] = self.body_index
        return out

    @classmethod
    def from_arrays(cls, name: str, arrays, source: dict | None = None) -> "BodyPart":
        """The part saved by :meth:`arrays`; a part that ``source`` says was subdivided, and
        whose arrays are the subdivision of a coarser part, knows that part again
        (:attr:`coarser`, :func:`undivide`).
        """
        rims = (
            tuple(np.split(np.asarray(arrays["rims"]), np.cumsum(arrays["rim_lengths"])[:-1]))
            if len(arrays["rim_lengths"])
            else ()
        )
        part = cls(
            name=name,
            vertices=np.asarray(arrays["vertices"], float),
            faces=np.asarray(arrays["faces"], np.int64),
            normals=np.asarray(arrays["normals"], float),
            uv=np.asarray(arrays["uv"], float),
            face_uv=np.asarray(arrays["face_uv"], np.int64),
            uv_vertex=np.asarray(arrays["uv_vertex"], np.int64),
            uv_scale=float(arrays["uv_scale"]),
            rims=rims,
            axis=np.asarray(arrays["axis"], float) if "axis" in arrays else None,
            body_index=np.asarray(arrays["body_index"], np.int64)
            if "body_index" in arrays
            else None,
            source=dict(source or {}),
        )
        coarser = undivide(part)
        return part if coarser is None else dataclasses.replace(part, coarser=coarser)

    def limb_frame(self, along: float) -> tuple[np.ndarray, np.ndarray, float]:
        """``(centre (3,), direction (3,), arc length s0 m)``: the point of the limb axis at
        fraction ``along`` of the part's extent along it, and the axis direction there.
        """
        if self.axis is None:
            raise ValueError(f"part {self.name!r} has no limb axis (not a limb)")
        if not 0.0 <= along <= 1.0:
            raise ValueError(f"along must lie in [0, 1] (fraction along the limb), got {along}")
        s = self.axial
        s0 = s.min() + along * (s.max() - s.min())
        line = self.axis  # arc length runs from line[0]
        seg_len = np.linalg.norm(np.diff(line, axis=0), axis=1)
        start = np.r_[0.0, np.cumsum(seg_len)[:-1]]
        k = int(np.clip(np.searchsorted(start, s0, "right") - 1, 0, len(seg_len) - 1))
        t = float(np.clip((s0 - start[k]) / seg_len[k], 0.0, 1.0))
        return line[k] + t * (line[k + 1] - line[k]), (line[k + 1] - line[k]) / seg_len[k], s0

    def subdivided(self, levels: int = 1) -> "BodyPart":
        """A finer copy: every triangle split into four at its edge midpoints, ``levels`` times
        (:func:`subdivide`).
        """
        part = self
        for _ in range(int(levels)):
            part = subdivide(part)
        return part

    def with_vertices(self, vertices: np.ndarray) -> "BodyPart":
        """A copy with other rest positions (normals recomputed)."""
        return dataclasses.replace(
            self, vertices=vertices, normals=vertex_normals(vertices, self.faces), coarser=None
        )


# --- construction ------------------------------------------------------------------------------
def _midpoints(pairs: np.ndarray, offset: int):
    """Unique sorted ``pairs`` ``(K, 2)`` -> ``(unique (E, 2), index of each pair's midpoint
    (K,) = offset + its unique row)``.
    """
    key, inv = np.unique(np.sort(pairs, axis=1), axis=0, return_inverse=True)
    return key, offset + inv.reshape(-1)


def subdivide(part: BodyPart) -> BodyPart:
    """``part`` with every triangle split into four at its edge midpoints (the surface itself
    unchanged): new vertices at the midpoints of the edges, their normals the normalised mean of
    the ends', UV corners at the midpoints of the UV edges (a seam edge gets one on each side of
    the chart), rims with their midpoints in order. The old vertices keep their indices; a new
    vertex has no body vertex (``body_index`` -1).
    """
    n, t = part.n_vertices, len(part.uv)
    f, fu = part.faces, part.face_uv
    corner_pairs = [(0, 1), (1, 2), (2, 0)]
    vpairs = np.concatenate([f[:, list(p)] for p in corner_pairs])  # (3M, 2)
    edges, vmid = _midpoints(vpairs, n)
    upairs = np.concatenate([fu[:, list(p)] for p in corner_pairs])
    uedges, umid = _midpoints(upairs, t)
    m = len(f)
    ab, bc, ca = vmid[:m], vmid[m : 2 * m], vmid[2 * m :]
    uab, ubc, uca = umid[:m], umid[m : 2 * m], umid[2 * m :]
    a, b, c = f.T
    ua, ub, uc = fu.T
    faces = np.concatenate(
        [np.stack(x, 1) for x in ((a, ab, ca), (ab, b, bc), (ca, bc, c), (ab, bc, ca))]
    )
    face_uv = np.concatenate(
        [np.stack(x, 1) for x in ((ua, uab, uca), (uab, ub, ubc), (uca, ubc, uc), (uab, ubc, uca))]
    )
    normals = part.normals[edges].sum(1)
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    # each new UV corner belongs to the midpoint vertex of its two corners' vertices
    uv_vertex = np.concatenate([part.uv_vertex, np.zeros(len(uedges), np.int64)])
    uv_vertex[umid] = vmid
    edge_of = {tuple(e): n + i for i, e in enumerate(edges)}

    def finer(rim):  # each rim vertex, then the midpoint to the next one
        out = []
        for p, q in zip(rim, np.roll(rim, -1)):
            out.append(p)
            if tuple(sorted((p, q))) in edge_of:  # a closed loop wraps around
                out.append(edge_of[tuple(sorted((p, q)))])
        return np.asarray(out, dtype=np.int64)

    rims = tuple(finer(r) for r in part.rims)
    body_index = (
        None
        if part.body_index is None
        else np.concatenate([part.body_index, -np.ones(len(edges), np.int64)])
    )
    source = {**part.source, "subdivisions": int(part.source.get("subdivisions", 0)) + 1}
    return BodyPart(
        part.name,
        np.concatenate([part.vertices, part.vertices[edges].mean(1)]),
        faces,
        np.concatenate([part.normals, normals]),
        np.concatenate([part.uv, part.uv[uedges].mean(1)]),
        face_uv,
        uv_vertex,
        part.uv_scale,
        rims,
        part.axis,
        body_index,
        source,
        coarser=part,
    )


def undivide(part: BodyPart) -> BodyPart | None:
    """The part that ``part`` was subdivided from (:func:`subdivide`), rebuilt from its arrays
    alone (its first vertices and UV corners, the outer corners of each face's four), where
    ``part.source`` counts a subdivision and subdividing that part gives ``part`` exactly;
    else ``None``. A part saved and read again (a scene file, a dataset) so keeps the part a
    press is meshed on (:mod:`fem.finer`).
    """
    levels = int(part.source.get("subdivisions", 0))
    if levels < 1 or len(part.faces) % 4:
        return None
    m = len(part.faces) // 4
    f, fu = part.faces, part.face_uv
    faces = np.stack([f[:m, 0], f[m : 2 * m, 1], f[2 * m : 3 * m, 2]], 1)
    face_uv = np.stack([fu[:m, 0], fu[m : 2 * m, 1], fu[2 * m : 3 * m, 2]], 1)
    n, t = int(faces.max(initial=-1)) + 1, int(face_uv.max(initial=-1)) + 1
    rims = tuple(r[::2] for r in part.rims)
    if not (0 < n < part.n_vertices and 0 < t < len(part.uv)) or any((r >= n).any() for r in rims):
        return None
    source = {**part.source, "subdivisions": levels - 1}
    if levels == 1:
        del source["subdivisions"]
    try:
        coarse = BodyPart(
            part.name,
            part.vertices[:n],
            faces,
            part.normals[:n],
            part.uv[:t],
            face_uv,
            part.uv_vertex[:t],
            part.uv_scale,
            rims,
            part.axis,
            None if part.body_index is None else part.body_index[:n],
            source,
        )
    except ValueError:  # not the first vertices of a subdivision
        return None
    again = subdivide(coarse)
    same = all(
        np.array_equal(getattr(again, k), getattr(part, k))
        for k in ("vertices", "faces", "normals", "uv", "face_uv", "uv_vertex")
    ) and len(again.rims) == len(part.rims)
    if not same or not all(np.array_equal(a, b) for a, b in zip(again.rims, part.rims)):
        return None
    return dataclasses.replace(coarse, coarser=undivide(coarse))


def _check_shape(name: str, arr, shape: tuple) -> None:
    a = np.asarray(arr)
    ok = a.ndim == len(shape) and all(s is None or s == d for s, d in zip(shape, a.shape))
    if not ok:
        want = "(" + ", ".join("N" if s is None else str(s) for s in shape) + ")"
        raise ValueError(f"BodyPart.{name} must have shape {want}, got {tuple(a.shape)}")


def difference(part: BodyPart, reference: BodyPart, atol: float = 1e-6) -> str:
    """What sets ``part`` apart from ``reference``, in words (``""`` when they are the same mesh,
    vertices equal as ``np.allclose`` with ``atol`` m has it): the name, the vertex count, the
    faces, or how far the vertices lie apart and which body each came from.
    """

    def where(p):
        src = p.source or {}
        ph = (src.get("options") or {}).get("phenotype")
        body = src.get("body", "an unknown body")
        return f"{body} {ph}" if ph else str(body)

    if part.name != reference.name:
        return f"the scene's part is {part.name!r}, the model's {reference.name!r}"
    if part.n_vertices != reference.n_vertices:
        return (
            f"the scene's {part.name} has {part.n_vertices} vertices, the model's "
            f"{reference.n_vertices} (another body model or resolution)"
        )
    if part.faces.shape != reference.faces.shape or not np.array_equal(part.faces, reference.faces):
        return (
            f"the scene's {part.name} has other faces (another mesh of {part.n_vertices} vertices)"
        )
    if not np.allclose(part.vertices, reference.vertices, atol=atol):
        gap = float(np.abs(part.vertices - reference.vertices).max())
        a, b = where(part), where(reference)
        body = f" (the scene's from {a}, the model's from {b})" if a != b else ""
        return (
            f"the same {part.n_vertices}-vertex {part.name} mesh, but its vertices lie up to "
            f"{gap * 1e3:.3g} mm from the model's: another body shape{body}"
        )
    return ""
