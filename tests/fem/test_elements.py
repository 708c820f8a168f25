"""Quadratic connectivity: one midpoint node per edge, shared by every tet that has the edge."""

import numpy as np

from fem.elements import EDGES, quadratic
from fem.mesh import shell_mesh
from stmpl.body.primitives import sheet


def test_each_edge_gets_one_midpoint_in_sorted_order():
    part = sheet(0.1, 0.1, 6, 6)
    mesh = shell_mesh(part, np.full(part.n_vertices, 0.005), layers=2)
    tets10, edges = quadratic(mesh.tets, mesh.n_nodes)
    pairs = np.sort(mesh.tets[:, EDGES].reshape(-1, 2), axis=1)
    expected = np.array(sorted({tuple(p) for p in pairs.tolist()}))
    np.testing.assert_array_equal(edges, expected)  # unique, sorted by (first, second)
    np.testing.assert_array_equal(tets10[:, :4], mesh.tets)
    mid = tets10[:, 4:] - mesh.n_nodes  # each midpoint names its tet's own edge
    np.testing.assert_array_equal(edges[mid].reshape(-1, 2), pairs)
