"""A press meshed on a coarser part and answered on a finer one.

The main job's arm is anny's plain left arm subdivided once
(:meth:`stmpl.part.BodyPart.subdivided`: every edge split at its midpoint, the surface
unchanged). In quadratic elements a mesh of the plain skin carries a node at every edge's
midpoint, so each vertex of the part subdivided once is a node of it: the answer there is the
solution's own value, no interpolation. So an object pressed on a subdivided part is solved
on the part it was subdivided from (:func:`meshed`), refined one level more near the object
(:func:`fem.simulate.press_solver`): the same mesh where the object presses, a coarser one
where the tissue barely moves, and answered on the finer part by :class:`FinerPart`. The
layered forearm under a disk on the main job's arm: 115k unknowns in place of 309k. An 8 mm
ball 4 mm into the forearm preset of a tube answered within 0.11 % of the reaction and 0.26 %
of the deepest displacement, with 84k unknowns in place of 135k (docs/tissue.md).
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from scipy.spatial import cKDTree

from fem.shapes import Surface
from stmpl.part import BodyPart

ON_NODE = 1e-7
"""m: how close a vertex of the finer part must lie to a node of the mesh to be that node."""


def meshed(part: BodyPart, thickness: np.ndarray, order: int) -> tuple[BodyPart, np.ndarray]:
    """``(part to mesh, its thickness (n,) m)`` for a press answered on ``part`` with
    ``thickness`` ``(N,)`` (m): the part it was subdivided from when the elements are quadratic
    (``order`` 2) and the thickness at each edge's midpoint is its ends' mean; else ``part``
    itself.
    """
    thickness = np.asarray(thickness, dtype=float)
    c = part.coarser
    if c is None or order != 2:
        return part, thickness
    n, e = c.n_vertices, c.edges
    if part.n_vertices != n + len(e) or not np.allclose(
        part.vertices[n:], c.vertices[e].mean(1), rtol=0, atol=ON_NODE
    ):
        return part, thickness
    if not np.allclose(thickness[n:], thickness[:n][e].mean(1), rtol=0, atol=1e-9):
        return part, thickness  # a thickness map of its own on the finer part: mesh that
    return c, thickness[:n]


class FinerPart:
    """How a contact answer on ``solver``'s skin reads on ``part``, a part whose every vertex
    is a skin node of the mesh (within :data:`ON_NODE`): a subdivision of the mesh's part, or
    the part itself.

    Attributes:
        part: the part the answers are given on.
        nodes: ``(N,)`` the node (index into the solver's ``n_all``) at each vertex of it.
        share: ``(N, n_all)`` sparse: how a force on each skin node is shared among the part's
            vertices (a node on a vertex gives it all; another, on a triangle of the part, gives
            its corners their barycentric shares: the transpose of linear interpolation, so
            the total is kept).
    """

    def __init__(self, solver, part: BodyPart):
        mesh = solver.mesh
        s = mesh.n_skin
        on_skin = (solver.edges < s).all(axis=1)  # a quadratic element's skin edge nodes
        skin = np.concatenate([np.arange(s), mesh.n_nodes + np.flatnonzero(on_skin)])
        x = solver.positions[skin]
        d, j = cKDTree(x).query(part.vertices)
        if d.max() > ON_NODE:
            k = int(np.argmax(d))
            raise ValueError(
                f"vertex {k} of {part.name} lies {1e3 * d[k]:.3g} mm from the mesh's nearest "
                "skin node: the part is not one the mesh answers on"
            )
        self.part, self.nodes = part, skin[j]
        # every skin node's share among the part's vertices
        d, vertex = part.tree.query(x)
        rows, cols, vals = (
            [vertex[d <= ON_NODE]],
            [skin[d <= ON_NODE]],
            [np.ones((d <= ON_NODE).sum())],
        )
        off = np.flatnonzero(d > ON_NODE)
        if len(off):
            face, _, _, bary = Surface(part.vertices, part.faces, 0.0).closest(x[off])
            # a node on an edge gives the third corner nothing, not round-off (the contact
            # area counts the vertices pressed)
            bary = np.where(bary < 1e-9, 0.0, bary)
            bary /= bary.sum(axis=1, keepdims=True)
            rows.append(part.faces[face].ravel())
            cols.append(np.repeat(skin[off], 3))
            vals.append(bary.ravel())
        self.share = sp.csr_matrix(
            (np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))),
            shape=(part.n_vertices, solver.n_all),
        )

    def displacement(self, u: np.ndarray) -> np.ndarray:
        """``(N, 3)``: the displacement ``u`` ``(n_all, 3)`` (m) at the part's vertices."""
        return u[self.nodes].copy()

    def pressure(self, forces: np.ndarray) -> np.ndarray:
        """``(N,)`` Pa: forces on the nodes ``(n_all,)`` (N) as a pressure on the part's
        vertices (each vertex's share over its area).
        """
        return np.asarray(self.share @ forces).ravel() / self.part.vertex_areas
