"""A triangle mesh as two arrays, with what contact asks of an object mesh (its triangles,
bounds, area, whether it is closed) and its rigid placement; the main job's hand travels as one,
so that a warm ``stmpl simulate`` does not import trimesh (half a second) only to hold arrays.
Meshes read from files and the shapes of :mod:`stmpl.contact.objects` stay ``trimesh.Trimesh``,
which offers the same attributes; contact takes either.
"""

from __future__ import annotations

import numpy as np


class Mesh:
    """``vertices`` ``(V, 3)`` (m) and ``faces`` ``(F, 3)`` vertex indices, counter-clockwise
    seen from outside.
    """

    def __init__(self, vertices, faces):
        v = np.array(vertices, dtype=np.float64)
        f = np.array(faces, dtype=np.int64)
        if v.ndim != 2 or v.shape[1] != 3 or f.ndim != 2 or f.shape[1] != 3:
            raise ValueError(
                f"a mesh needs (V, 3) vertices and (F, 3) faces, got {v.shape} and {f.shape}"
            )
        if f.size and (f.min() < 0 or f.max() >= len(v)):
            raise ValueError(f"faces index vertices 0..{len(v) - 1}, got {f.min()}..{f.max()}")
        self.vertices, self.faces = v, f

    @property
    def triangles(self) -> np.ndarray:
        """``(F, 3, 3)`` each face's corners, m."""
        return self.vertices[self.faces]

    @property
    def bounds(self) -> np.ndarray:
        """``(2, 3)`` the lowest and highest corner of the box round the vertices, m."""
        return np.stack([self.vertices.min(0), self.vertices.max(0)])

    @property
    def extents(self) -> np.ndarray:
        """``(3,)`` the box's size, m."""
        return np.ptp(self.vertices, axis=0)

    @property
    def area(self) -> float:
        """The surface's area, m^2."""
        t = self.triangles
        return float(
            0.5 * np.linalg.norm(np.cross(t[:, 1] - t[:, 0], t[:, 2] - t[:, 0]), axis=1).sum()
        )

    @property
    def is_watertight(self) -> bool:
        """Whether every edge joins exactly two faces that run along it in opposite senses (a
        closed, consistently wound surface, as trimesh reads it).
        """
        f = self.faces
        directed = np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]])
        if len(np.unique(directed, axis=0)) != len(directed):  # an edge run twice one way
            return False
        undirected = np.sort(directed, axis=1)
        _, counts = np.unique(undirected, axis=0, return_counts=True)
        return bool(len(f)) and bool(np.all(counts == 2))

    def copy(self) -> "Mesh":
        return Mesh(self.vertices, self.faces)

    def apply_transform(self, matrix) -> "Mesh":
        """Move the vertices by the ``(4, 4)`` rigid transform ``matrix``, in place; returns the
        mesh (as trimesh's does).
        """
        m = np.asarray(matrix, dtype=np.float64)
        self.vertices = self.vertices @ m[:3, :3].T + m[:3, 3]
        return self
