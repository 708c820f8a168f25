"""Lagrange tetrahedra of order 1 (4 nodes) and 2 (10 nodes), in barycentric coordinates.

For a straight-sided tetrahedron with barycentric coordinates ``L_0..L_3`` (``grad L_k`` constant),
the shape functions are::

    P1:  N_k = L_k
    P2:  N_k = L_k (2 L_k - 1) at the vertices, N_ij = 4 L_i L_j at the edge midpoints

so ``grad N_a = sum_k (dN_a / dL_k) grad L_k``. Edge order: 01, 12, 02, 03, 13, 23. Quadrature is
exact to the order the stiffness needs on straight elements (P1: one point, P2: four points).
Triangles (the skin faces that carry pressure) use the same numbering: P2 edges 01, 12, 20.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

EDGES = np.array([[0, 1], [1, 2], [0, 2], [0, 3], [1, 3], [2, 3]])
TRI_EDGES = np.array([[0, 1], [1, 2], [2, 0]])

_a, _b = 0.5854101966249685, 0.1381966011250105


@dataclass(frozen=True)
class TetElement:
    """Shape-function data of one tetrahedron type.

    Attributes:
        order: 1 or 2. n: nodes per element.
        points: ``(Q, 4)`` quadrature points (barycentric). weights: ``(Q,)`` summing to 1.
        dN: ``(Q, n, 4)`` derivatives ``dN_a / dL_k`` at the points.
    """

    order: int
    n: int
    points: np.ndarray
    weights: np.ndarray
    dN: np.ndarray


def _dN_p2(L: np.ndarray) -> np.ndarray:
    """``(Q, 10, 4)`` derivatives of the P2 shape functions at barycentric points ``(Q, 4)``."""
    Q = len(L)
    d = np.zeros((Q, 10, 4))
    for k in range(4):
        d[:, k, k] = 4 * L[:, k] - 1
    for e, (i, j) in enumerate(EDGES):
        d[:, 4 + e, i] = 4 * L[:, j]
        d[:, 4 + e, j] = 4 * L[:, i]
    return d


P1 = TetElement(
    1, 4, np.full((1, 4), 0.25), np.ones(1), np.broadcast_to(np.eye(4), (1, 4, 4)).copy()
)
_pts = np.full((4, 4), _b) + np.eye(4) * (_a - _b)
P2 = TetElement(2, 10, _pts, np.full(4, 0.25), _dN_p2(_pts))
ELEMENTS = {1: P1, 2: P2}


def shape_p2(L: np.ndarray) -> np.ndarray:
    """``(Q, 10)`` P2 shape function values at barycentric points ``(Q, 4)``."""
    N = np.empty((len(L), 10))
    N[:, :4] = L * (2 * L - 1)
    for e, (i, j) in enumerate(EDGES):
        N[:, 4 + e] = 4 * L[:, i] * L[:, j]
    return N


def quadratic(tets: np.ndarray, n_nodes: int):
    """P2 connectivity from P1 tets ``(T, 4)``: ``(tets10 (T, 10), edges (E, 2))``; the
    midpoint of edge ``e`` is node ``n_nodes + e``.
    """
    e = np.sort(tets[:, EDGES].reshape(-1, 2), axis=1).astype(np.int64)
    # one integer per edge: sorting integers is several times faster than sorting rows, and
    # releases the GIL (a press answered meanwhile in another thread is not held up)
    keys, inv = np.unique(e[:, 0] * n_nodes + e[:, 1], return_inverse=True)
    edges = np.stack([keys // n_nodes, keys % n_nodes], axis=1).astype(tets.dtype)
    return np.concatenate([tets, n_nodes + inv.reshape(-1, 6)], axis=1), edges


# Triangle quadrature of degree 4 (6 points; Strang & Fix), barycentric, weights sum to 1.
_t1, _t2 = 0.445948490915965, 0.091576213509771
_w1, _w2 = 0.223381589678011, 0.109951743655322
TRI_POINTS = np.array(
    [
        [_t1, _t1, 1 - 2 * _t1],
        [_t1, 1 - 2 * _t1, _t1],
        [1 - 2 * _t1, _t1, _t1],
        [_t2, _t2, 1 - 2 * _t2],
        [_t2, 1 - 2 * _t2, _t2],
        [1 - 2 * _t2, _t2, _t2],
    ]
)
TRI_WEIGHTS = np.array([_w1] * 3 + [_w2] * 3)


def tri_shape(order: int, L: np.ndarray) -> np.ndarray:
    """``(Q, 3 or 6)`` triangle shape functions (P1 or P2) at barycentric points ``(Q, 3)``."""
    if order == 1:
        return L.copy()
    N = np.empty((len(L), 6))
    N[:, :3] = L * (2 * L - 1)
    for e, (i, j) in enumerate(TRI_EDGES):
        N[:, 3 + e] = 4 * L[:, i] * L[:, j]
    return N
