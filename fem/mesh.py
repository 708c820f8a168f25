"""The tissue shell: a tetrahedral mesh of the soft layer between the skin and the fixed inner
surface.

The skin is the body part's surface, optionally refined by midpoint subdivision (each triangle into
four; new nodes on the flat triangles, so the skin keeps its exact shape). The inner surface is the
skin moved inward by the local thickness along smoothed normals. ``layers`` node layers split the
thickness evenly; each triangle between two layers is a prism cut into three tetrahedra by the rule
"each quad's diagonal starts at its lower-numbered skin vertex", which makes neighbouring prisms
conform without any bookkeeping.

Node numbering: ``node = layer * S + s`` for skin node ``s`` in ``[0, S)`` and layer ``0`` (skin)
to ``layers`` (inner, fixed). The body part's vertices are the first ``N`` skin nodes, so a
displacement on the part is ``u[:N]``.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import cached_property

import numpy as np
import scipy.sparse as sp
from scipy.spatial import cKDTree

from fem.elements import TRI_EDGES, TRI_POINTS, TRI_WEIGHTS, tri_shape
from stmpl.geometry import triangle_areas
from stmpl.part import BodyPart


@dataclass(frozen=True, eq=False)
class Quality:
    """Element quality of a tet mesh: volumes in m^3, dihedral angles in degrees."""

    n_tets: int
    min_volume: float
    max_volume: float
    n_inverted: int
    min_dihedral: float
    max_dihedral: float

    def to_dict(self) -> dict:
        return {k: getattr(self, k) for k in self.__dataclass_fields__}

    def __str__(self) -> str:
        return (
            f"{self.n_tets} tets, volume {self.min_volume:.3g}..{self.max_volume:.3g} m^3, "
            f"{self.n_inverted} inverted, dihedral {self.min_dihedral:.1f}..."
            f"{self.max_dihedral:.1f} deg"
        )


@dataclass(frozen=True, eq=False)
class ShellMesh:
    """A tissue shell of P1 tetrahedra over a body part.

    Attributes:
        part: the body part whose skin is layer 0.
        nodes: ``(M, 3)`` rest positions, m; ``M = S * (layers + 1)``.
        tets: ``(T, 4)`` node indices, positively oriented.
        skin_faces: ``(K, 3)`` skin triangles over skin nodes ``[0, S)``, outward.
        skin_normals: ``(S, 3)`` outward unit skin normals (the part's, interpolated).
        thickness: ``(S,)`` tissue thickness at each skin node, m.
        interp: ``(S, N)`` sparse map from part-vertex values to skin-node values (linear).
        layers: number of element layers through the thickness.
        subdivisions: midpoint subdivision levels applied to the skin.
    """

    part: BodyPart
    nodes: np.ndarray
    tets: np.ndarray
    skin_faces: np.ndarray
    skin_normals: np.ndarray
    thickness: np.ndarray
    interp: sp.csr_matrix
    layers: int
    subdivisions: int
    info: dict = field(default_factory=dict)

    @property
    def n_skin(self) -> int:
        """S: skin nodes (part vertices first)."""
        return len(self.skin_normals)

    @property
    def n_nodes(self) -> int:
        return len(self.nodes)

    @property
    def part_nodes(self) -> np.ndarray:
        """``(N,)`` the skin node of each part vertex."""
        return np.arange(self.part.n_vertices)

    @property
    def inner_nodes(self) -> np.ndarray:
        """``(S,)`` the nodes of the fixed inner surface."""
        return np.arange(self.layers * self.n_skin, (self.layers + 1) * self.n_skin)

    @property
    def rim_nodes(self) -> np.ndarray:
        """Nodes on the part's cut rims, all layers (the tissue goes on past the cut)."""
        if not self.part.rims:
            return np.zeros(0, dtype=np.int64)
        rim = np.concatenate(self.part.rims)
        return (rim[None, :] + self.n_skin * np.arange(self.layers + 1)[:, None]).ravel()

    @cached_property
    def tet_layers(self) -> np.ndarray:
        """``(T,)`` the element layer of each tetrahedron, 0 under the skin to ``layers - 1``
        on the inner surface.
        """
        return np.repeat(np.arange(self.layers), len(self.tets) // self.layers)

    @cached_property
    def volumes(self) -> np.ndarray:
        """``(T,)`` rest volumes, m^3."""
        return tet_volumes(self.nodes, self.tets)

    @cached_property
    def skin_face_areas(self) -> np.ndarray:
        """``(K,)`` areas of the skin triangles, m^2."""
        return triangle_areas(self.nodes, self.skin_faces)

    @cached_property
    def skin_areas(self) -> np.ndarray:
        """``(S,)`` barycentric skin-node areas, m^2."""
        out = np.zeros(self.n_skin)
        np.add.at(out, self.skin_faces.ravel(), np.repeat(self.skin_face_areas / 3, 3))
        return out

    def quality(self) -> Quality:
        """Volumes and dihedral angles of all elements."""
        vol = self.volumes
        dih = dihedral_angles(self.nodes, self.tets)
        return Quality(
            len(self.tets),
            float(vol.min()),
            float(vol.max()),
            int((vol <= 0).sum()),
            float(dih.min()),
            float(dih.max()),
        )

    def quadratic_forces(self, force: np.ndarray, edges: np.ndarray) -> np.ndarray:
        """``(M + E, 3)`` consistent nodal forces of quadratic elements for per-vertex normal
        forces ``(N,)`` (N): the linear pressure they make integrated against the 6-node skin
        triangles (nodes, then the midpoints of ``edges`` ``(E, 2)``, sorted pairs).
        """
        forces = self.quadratic_force_operator(edges) @ np.asarray(force, float)
        return forces.reshape(-1, 3)

    def quadratic_force_operator(self, edges: np.ndarray) -> sp.csr_matrix:
        """``(3 (M + E), N)`` sparse map from per-vertex normal forces (N) to the flattened
        :meth:`quadratic_forces` (one column per vertex: a unit force on it).
        """
        n_all = self.n_nodes + len(edges)
        tri = self.skin_faces
        key = edges[:, 0] * n_all + edges[:, 1]
        te = np.sort(tri[:, TRI_EDGES], axis=2)  # (K, 3, 2)
        mid = self.n_nodes + np.searchsorted(key, te[..., 0] * n_all + te[..., 1])
        nodes6 = np.concatenate([tri, mid], axis=1)  # (K, 6)
        # int p N_b over a face, p linear from its corners' pressures p_a: area C[a, b] p_a
        C = (TRI_WEIGHTS[:, None] * TRI_POINTS).T @ tri_shape(2, TRI_POINTS)  # (3, 6)
        vals = self.skin_face_areas[:, None, None] * C[None]  # (K, 3, 6)
        rows = np.broadcast_to(nodes6[:, None, :], vals.shape)
        cols = np.broadcast_to(tri[:, :, None], vals.shape)
        push = sp.csr_matrix(
            (vals.ravel(), (rows.ravel(), cols.ravel())), shape=(n_all, self.n_skin)
        )  # node magnitudes from skin-node pressures
        pressure = self.interp @ sp.diags(1.0 / self.part.vertex_areas)  # (S, N)
        normals = np.zeros((n_all, 3))
        normals[: self.n_skin] = self.skin_normals
        skin_edge = (edges[:, 0] < self.n_skin) & (edges[:, 1] < self.n_skin)
        nm = self.skin_normals[edges[skin_edge, 0]] + self.skin_normals[edges[skin_edge, 1]]
        normals[self.n_nodes + np.flatnonzero(skin_edge)] = nm / np.linalg.norm(
            nm, axis=1, keepdims=True
        )
        spread = sp.kron(sp.eye(n_all, format="csr"), np.ones((3, 1)), format="csr")
        return (sp.diags(-normals.ravel()) @ spread @ (push @ pressure)).tocsr()

    def nodal_forces(self, force: np.ndarray, mode: str = "traction") -> np.ndarray:
        """``(M, 3)`` nodal force vectors (N) for per-vertex normal forces on the part.

        Args:
            force: ``(N,)`` force magnitudes per part vertex, N, pushing along the inward normal.
            mode: ``"traction"`` turns them into a pressure ``p_i = F_i / A_i`` (``A_i`` the
                vertex area), interpolates it linearly over the skin and integrates it exactly, so
                the total force is kept and the load converges under mesh refinement;
                ``"nodal"`` puts ``F_i`` on the part vertices' nodes as point loads (the paper's
                literal boundary condition; mesh-dependent once the skin is subdivided).
        """
        force = np.asarray(force, dtype=float)
        n = self.part.n_vertices
        if force.shape != (n,):
            raise ValueError(f"force must have shape ({n},), got {force.shape}")
        out = np.zeros((self.n_nodes, 3))
        if mode == "nodal":
            out[:n] = -force[:, None] * self.skin_normals[:n]
            return out
        if mode != "traction":
            raise ValueError(f"unknown load mode {mode!r}; use 'traction' or 'nodal'")
        p = self.interp @ (force / self.part.vertex_areas)
        pf = p[self.skin_faces]  # (K, 3)
        load = (
            self.skin_face_areas[:, None] * (pf + pf.sum(1, keepdims=True)) / 12
        )  # int p phi_a over each face
        mag = np.zeros(self.n_skin)
        np.add.at(mag, self.skin_faces.ravel(), load.ravel())
        out[: self.n_skin] = -mag[:, None] * self.skin_normals
        return out

    def to_vtu(self, path, point_data: dict | None = None, cell_data: dict | None = None):
        """Write the mesh (and ``(M,)``/``(M, 3)`` point arrays) as a VTU file for ParaView."""
        import meshio  # deferred: the .vtu export only

        pd = {"layer": np.repeat(np.arange(self.layers + 1), self.n_skin).astype(float)}
        for k, v in (point_data or {}).items():
            v = np.asarray(v, dtype=float)
            if v.shape[0] != self.n_nodes:
                raise ValueError(
                    f"point data {k!r} has {v.shape[0]} rows, mesh has {self.n_nodes} nodes"
                )
            pd[k] = v
        cd = {"volume": [self.volumes]}
        cd.update({k: [np.asarray(v, dtype=float)] for k, v in (cell_data or {}).items()})
        meshio.Mesh(self.nodes, [("tetra", self.tets)], point_data=pd, cell_data=cd).write(path)
        return path


def shell_mesh(
    part: BodyPart,
    thickness: np.ndarray,
    layers: int = 2,
    subdivisions: int = 0,
    refine_near: np.ndarray | None = None,
    refine_radius: float = 0.03,
    normal_smoothing: int = 2,
    fractions: np.ndarray | None = None,
) -> ShellMesh:
    """Build the tissue shell of ``part`` with per-vertex ``thickness`` ``(N,)`` in metres.

    ``fractions``: the node layers' depths as shares of the thickness, from 0 (skin) to 1
    (inner surface), rising: ``(layers + 1,)`` for every vertex alike, or ``(layers + 1, N)``
    per vertex (tissue layers of their own thickness maps); default ``layers`` even layers.

    ``subdivisions`` levels of midpoint refinement apply to the whole skin, or, given
    ``refine_near`` ``(K, 3)`` points (m; e.g. the loaded vertices), only to the faces with a
    vertex within ``refine_radius`` (m) of one of them, closed conformingly (red-green).

    Raises ``ValueError`` for non-finite or non-positive thickness, degenerate or non-manifold
    skin, or a thickness that folds the inner surface (larger than the local radius of curvature).
    """
    n = part.n_vertices
    t = np.asarray(thickness, dtype=float)
    if t.shape != (n,):
        raise ValueError(f"thickness must have shape ({n},), got {t.shape}")
    if not np.all(np.isfinite(t)) or t.min() <= 0:
        i = int(np.argmin(np.where(np.isfinite(t), t, -np.inf)))
        raise ValueError(f"thickness must be finite and > 0; vertex {i} has {t[i]!r} m")
    if int(layers) != layers or layers < 1:
        raise ValueError(f"layers must be an integer >= 1, got {layers!r}")
    if int(subdivisions) != subdivisions or not 0 <= subdivisions <= 4:
        raise ValueError(f"subdivisions must be an integer in 0..4, got {subdivisions!r}")
    check_surface(part.vertices, part.faces)

    offset = smooth_normals(part.vertices, part.faces, part.normals, normal_smoothing)
    x, f, normals, interp = (
        part.vertices.copy(),
        part.faces.copy(),
        part.normals.copy(),
        sp.identity(n, format="csr"),
    )
    if refine_near is not None:
        pts = np.asarray(refine_near, dtype=float).reshape(-1, 3)
        if len(pts) == 0 or not np.all(np.isfinite(pts)) or not refine_radius > 0:
            raise ValueError(
                "refine_near needs finite (K, 3) points, K >= 1, and refine_radius > 0"
            )
        tree = cKDTree(pts)
    for _ in range(subdivisions):
        marked = None
        if refine_near is not None:
            near = tree.query(x, distance_upper_bound=refine_radius)[0] <= refine_radius
            marked = near[f].any(1)
        x, f, P = midpoint_subdivide(x, f, marked)
        interp = (P @ interp).tocsr()
        normals = _unit(P @ normals)
        offset = _unit(P @ offset)
    thick = interp @ t
    S = len(x)
    frac = _fractions(fractions, layers, n)
    frac = np.stack([interp @ f for f in frac]) if frac.ndim == 2 else frac[:, None]
    nodes = np.concatenate([x - (a * thick)[:, None] * offset for a in frac])
    tets = np.concatenate([_prism_tets(f, k * S, (k + 1) * S) for k in range(layers)])
    vol = tet_volumes(nodes, tets)
    tets[vol < 0] = tets[vol < 0][:, [0, 2, 1, 3]]
    mesh = ShellMesh(
        part,
        nodes,
        tets,
        f,
        normals,
        thick,
        interp,
        int(layers),
        int(subdivisions),
        info={
            "normal_smoothing": normal_smoothing,
            "refine_radius": None if refine_near is None else refine_radius,
        },
    )
    _check_folds(mesh, f, x, offset, thick)
    return mesh


def _fractions(fractions, layers: int, n: int) -> np.ndarray:
    """The node layers' depth shares, checked: ``(layers + 1,)`` or ``(layers + 1, n)``."""
    if fractions is None:
        return np.linspace(0.0, 1.0, layers + 1)
    f = np.asarray(fractions, dtype=float)
    if f.shape not in ((layers + 1,), (layers + 1, n)):
        raise ValueError(
            f"fractions must have shape ({layers + 1},) or ({layers + 1}, {n}), got {f.shape}"
        )
    if not np.all(np.isfinite(f)) or np.any(f[0] != 0) or np.any(f[-1] != 1):
        raise ValueError("fractions must be finite, 0 at the skin and 1 at the inner surface")
    if np.any(np.diff(f, axis=0) <= 0):
        raise ValueError("fractions must rise strictly from the skin inward")
    return f


def check_surface(vertices: np.ndarray, faces: np.ndarray) -> None:
    """Raise ``ValueError`` for a degenerate (zero-area) or non-manifold triangle mesh."""
    if not np.all(np.isfinite(vertices)):
        raise ValueError("surface has non-finite vertex coordinates")
    area = triangle_areas(vertices, faces)
    tiny = 1e-10 * max(area.mean(), 1e-30)
    if np.any(area <= tiny):
        i = int(np.argmin(area))
        raise ValueError(
            f"degenerate surface: face {i} {faces[i].tolist()} has area {area[i]:.3g} m^2"
        )
    e = np.sort(np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]]), axis=1)
    uniq, counts = np.unique(e, axis=0, return_counts=True)
    if np.any(counts > 2):
        bad = uniq[counts > 2][0]
        raise ValueError(
            f"non-manifold surface: edge {bad.tolist()} is shared by {counts.max()} faces"
        )
    # consistent orientation: each interior edge is used once in each direction
    d = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])
    _, dcounts = np.unique(d, axis=0, return_counts=True)
    if np.any(dcounts > 1):
        raise ValueError("surface faces are not consistently oriented")


def smooth_normals(
    vertices: np.ndarray, faces: np.ndarray, normals: np.ndarray, iterations: int = 2
) -> np.ndarray:
    """``(N, 3)`` unit normals averaged with their edge neighbours ``iterations`` times."""
    n = len(vertices)
    e = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])
    A = sp.coo_matrix((np.ones(len(e)), (e[:, 0], e[:, 1])), shape=(n, n)).tocsr()
    A = ((A + A.T) > 0).astype(float) + sp.identity(n)
    out = np.asarray(normals, dtype=float)
    for _ in range(iterations):
        out = _unit(A @ out)
    return out


def midpoint_subdivide(vertices: np.ndarray, faces: np.ndarray, marked: np.ndarray | None = None):
    """Refine triangles at their edge midpoints, conformingly (red-green refinement).

    Marked faces (all when ``marked`` is ``None``) split into four; the marks spread until no
    face has exactly two split edges; a face with one split edge is bisected through it.

    Returns ``(vertices (N + E, 3), faces, P)`` with ``P`` the ``(N + E, N)`` sparse
    linear-interpolation map (old vertices first, then one midpoint per split edge).
    """
    n, m = len(vertices), len(faces)
    e = np.sort(np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]]), axis=1)
    edges, inv = np.unique(e, axis=0, return_inverse=True)
    fe = inv.reshape(3, m).T  # (M, 3) edge ab, bc, ca
    split = np.zeros(len(edges), dtype=bool)
    split[fe[np.ones(m, bool) if marked is None else np.asarray(marked, bool)].ravel()] = True
    while True:
        k = split[fe].sum(1)
        grow = k == 2
        if not grow.any():
            break
        split[fe[grow].ravel()] = True
    mid = np.full(len(edges), -1)
    mid[split] = n + np.arange(split.sum())
    se = edges[split]
    rows = np.concatenate([np.arange(n), np.repeat(np.arange(len(se)) + n, 2)])
    cols = np.concatenate([np.arange(n), se.ravel()])
    vals = np.concatenate([np.ones(n), np.full(2 * len(se), 0.5)])
    P = sp.csr_matrix((vals, (rows, cols)), shape=(n + len(se), n))
    k = split[fe].sum(1)
    a, b, c = faces.T
    ab, bc, ca = mid[fe].T
    red = k == 3
    out = [
        faces[k == 0],
        np.stack([a, ab, ca], 1)[red],
        np.stack([ab, b, bc], 1)[red],
        np.stack([ca, bc, c], 1)[red],
        np.stack([ab, bc, ca], 1)[red],
    ]
    for j in range(3):  # green: split edge j
        g = (k == 1) & split[fe[:, j]]
        p, q, r = np.roll(faces, -j, axis=1)[g].T  # split edge is p-q
        mpq = mid[fe[g, j]]
        out += [np.stack([p, mpq, r], 1), np.stack([mpq, q, r], 1)]
    return P @ vertices, np.concatenate(out), P


def tet_volumes(nodes: np.ndarray, tets: np.ndarray) -> np.ndarray:
    """``(T,)`` signed volumes, m^3 (positive for right-handed ``(x1-x0, x2-x0, x3-x0)``)."""
    x = nodes[tets]
    return (
        np.einsum("ti,ti->t", np.cross(x[:, 1] - x[:, 0], x[:, 2] - x[:, 0]), x[:, 3] - x[:, 0])
        / 6.0
    )


def dihedral_angles(nodes: np.ndarray, tets: np.ndarray) -> np.ndarray:
    """``(T, 6)`` interior dihedral angles at the six edges, degrees."""
    x = nodes[tets]
    faces = [(1, 2, 3), (0, 3, 2), (0, 1, 3), (0, 2, 1)]  # opposite vertex 0..3
    nrm = []
    for i, j, k in faces:
        c = np.cross(x[:, j] - x[:, i], x[:, k] - x[:, i])
        nrm.append(c / np.maximum(np.linalg.norm(c, axis=1, keepdims=True), 1e-300))
    out = [
        np.pi - np.arccos(np.clip(np.einsum("ti,ti->t", nrm[a], nrm[b]), -1, 1))
        for a in range(4)
        for b in range(a + 1, 4)
    ]
    return np.degrees(np.stack(out, 1))


def _prism_tets(faces: np.ndarray, lo: int, hi: int) -> np.ndarray:
    """Three tets per prism between layer offsets ``lo`` (bottom) and ``hi`` (top).

    With skin indices sorted ``a < b < c`` every quad's diagonal joins the lower-numbered
    bottom vertex to the higher-numbered top vertex, the same choice from both sides.
    """
    a, b, c = np.sort(faces, axis=1).T
    return np.concatenate(
        [
            np.stack([a + lo, b + lo, c + lo, c + hi], 1),
            np.stack([a + lo, b + lo, b + hi, c + hi], 1),
            np.stack([a + lo, a + hi, b + hi, c + hi], 1),
        ]
    )


def _check_folds(mesh: ShellMesh, faces, skin, offset, thick) -> None:
    """Raise if the inner surface folds (a face flips) or any element is inverted or flat."""
    inner = skin - thick[:, None] * offset
    n_out = np.cross(skin[faces[:, 1]] - skin[faces[:, 0]], skin[faces[:, 2]] - skin[faces[:, 0]])
    n_in = np.cross(
        inner[faces[:, 1]] - inner[faces[:, 0]], inner[faces[:, 2]] - inner[faces[:, 0]]
    )
    flipped = np.einsum("ti,ti->t", n_out, n_in) <= 0
    vol = tet_volumes(mesh.nodes, mesh.tets)
    tiny = 1e-6 * np.abs(vol).mean()
    bad_tet = np.abs(vol) <= tiny
    if flipped.any() or bad_tet.any():
        if flipped.any():
            vert = int(faces[np.flatnonzero(flipped)[0], 0])
        else:
            vert = int(mesh.tets[np.flatnonzero(bad_tet)[0], 0] % mesh.n_skin)
        r = _curvature_radius(skin, faces, offset)[vert]
        raise ValueError(
            f"tissue thickness {1e3 * thick[vert]:.2f} mm at skin node {vert} folds the inner "
            f"surface (local radius of curvature about {1e3 * r:.1f} mm); "
            f"{int(flipped.sum())} inner faces flip, {int(bad_tet.sum())} elements are flat"
        )


def room(part: BodyPart, normal_smoothing: int = 2, share: float = 0.6) -> np.ndarray:
    """``(N,)`` the depth (m) a shell may reach under each vertex of ``part`` without folding:
    ``share`` of the smallest radius of curvature over the vertex's ring of neighbours (the
    offset direction being the smoothed normals the shell uses).
    """
    offset = smooth_normals(part.vertices, part.faces, part.normals, normal_smoothing)
    r = _curvature_radius(part.vertices, part.faces, offset)
    adjacency = part.adjacency.tocsr()
    ring = np.minimum.reduceat(r[adjacency.indices], adjacency.indptr[:-1])
    return share * np.minimum(r, ring)


def _curvature_radius(x, faces, n) -> np.ndarray:
    """``(S,)`` smallest radius of normal curvature over each node's edges (m)."""
    e = np.unique(
        np.sort(np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]]), axis=1),
        axis=0,
    )
    d = x[e[:, 0]] - x[e[:, 1]]
    k = np.abs(np.einsum("ti,ti->t", n[e[:, 0]] - n[e[:, 1]], d)) / np.einsum("ti,ti->t", d, d)
    kmax = np.zeros(len(x))
    np.maximum.at(kmax, e[:, 0], k)
    np.maximum.at(kmax, e[:, 1], k)
    return 1.0 / np.maximum(kmax, 1e-12)


def _unit(v) -> np.ndarray:
    v = np.asarray(v)
    return v / np.maximum(np.linalg.norm(v, axis=1, keepdims=True), 1e-300)
