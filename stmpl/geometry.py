"""Plain functions over triangle meshes (points ``(N, 3)``, faces ``(M, 3)``): normals, areas,
boundary loops, connected pieces, projection on a polyline.
"""

import numpy as np
import scipy.sparse as sp
from scipy.sparse import csgraph


def vertex_normals(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """``(N, 3)`` area-weighted unit vertex normals of a triangle mesh."""
    v = vertices[faces]
    fn = np.cross(v[:, 1] - v[:, 0], v[:, 2] - v[:, 0])
    n = np.zeros_like(vertices, dtype=float)
    for k in range(3):
        np.add.at(n, faces[:, k], fn)
    length = np.linalg.norm(n, axis=1, keepdims=True)
    return n / np.where(length > 0, length, 1.0)


def boundary_loops(faces: np.ndarray) -> tuple[np.ndarray, ...]:
    """Ordered loops of boundary vertices (edges used by one face), longest first."""
    directed = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])
    key = np.sort(directed, axis=1)
    _, inv, counts = np.unique(key, axis=0, return_inverse=True, return_counts=True)
    boundary = directed[counts[inv.ravel()] == 1]
    nxt = {int(a): int(b) for a, b in boundary}
    loops, seen = [], set()
    for start in nxt:
        if start in seen:
            continue
        loop, cur = [], start
        while cur not in seen and cur in nxt:
            seen.add(cur)
            loop.append(cur)
            cur = nxt[cur]
        loops.append(np.array(loop, np.int64))
    return tuple(sorted(loops, key=len, reverse=True))


def project_on_polyline(points: np.ndarray, line: np.ndarray) -> np.ndarray:
    """``(N,)`` arc length along a polyline ``(K, 3)`` of each point's nearest projection."""
    a, b = line[:-1], line[1:]
    d = b - a
    seg_len = np.linalg.norm(d, axis=1)
    t = np.einsum("nkj,kj->nk", points[:, None] - a[None], d) / seg_len**2
    t = np.clip(t, 0.0, 1.0)
    foot = a[None] + t[..., None] * d[None]
    k = np.linalg.norm(points[:, None] - foot, axis=2).argmin(axis=1)
    start = np.concatenate([[0.0], np.cumsum(seg_len)[:-1]])
    return start[k] + t[np.arange(len(points)), k] * seg_len[k]


def largest_component(faces: np.ndarray, n: int) -> np.ndarray:
    e = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]]])
    adj = sp.coo_matrix((np.ones(len(e)), (e[:, 0], e[:, 1])), shape=(n, n))
    _, label = csgraph.connected_components(adj, directed=False)
    face_label = label[faces[:, 0]]
    return face_label == np.bincount(face_label).argmax()


def triangle_areas_of(tri: np.ndarray) -> np.ndarray:
    return 0.5 * np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1)


def triangle_areas(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """``(M,)`` areas of triangles ``faces`` ``(M, 3)`` over ``vertices`` ``(N, 3)``, m^2."""
    return triangle_areas_of(np.asarray(vertices)[faces])
