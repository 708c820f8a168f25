"""Plain functions over triangle meshes (points ``(N, 3)``, faces ``(M, 3)``): normals, areas,
boundary loops, connected pieces, projection on a polyline, closest points on triangles.
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


def closest_points(tri: np.ndarray, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(c (K, 3), weights (K, 3))``: the point of each triangle ``tri`` ``(K, 3, 3)``
    closest to ``x`` ``(K, 3)`` and its barycentric weights: the projection on the plane if it
    falls inside, else the nearest point of the three edges. Exact at any scale (no absolute
    tolerances: a millimetre triangle is as good as a metre one).
    """
    a, b, c = tri[:, 0], tri[:, 1], tri[:, 2]
    ab, ac, ap = b - a, c - a, x - a
    d00 = np.einsum("ki,ki->k", ab, ab)
    d01 = np.einsum("ki,ki->k", ab, ac)
    d11 = np.einsum("ki,ki->k", ac, ac)
    d20 = np.einsum("ki,ki->k", ap, ab)
    d21 = np.einsum("ki,ki->k", ap, ac)
    den = d00 * d11 - d01**2
    ok = den > 1e-12 * np.maximum(d00 * d11, 1e-300)
    den = np.where(ok, den, 1.0)
    v = (d11 * d20 - d01 * d21) / den
    w = (d00 * d21 - d01 * d20) / den
    weights = np.stack([1 - v - w, v, w], axis=1)
    best = np.einsum("kj,kji->ki", weights, tri)
    inside = ok & (weights.min(axis=1) >= 0)
    dist = np.where(inside, np.linalg.norm(x - best, axis=1), np.inf)
    for i, j in ((0, 1), (1, 2), (2, 0)):
        s0, s1 = tri[:, i], tri[:, j]
        e = s1 - s0
        t = np.einsum("ki,ki->k", x - s0, e) / np.maximum(np.einsum("ki,ki->k", e, e), 1e-300)
        t = np.clip(t, 0.0, 1.0)
        q = s0 + t[:, None] * e
        d = np.linalg.norm(x - q, axis=1)
        closer = d < dist
        best[closer], dist[closer] = q[closer], d[closer]
        wq = np.zeros((int(closer.sum()), 3))
        wq[:, i], wq[:, j] = 1 - t[closer], t[closer]
        weights[closer] = wq
    return best, weights
