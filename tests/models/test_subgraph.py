"""The subgraph of an answer at fidelity auto: the compiled kernel against its NumPy twin, and
the order the network's steps rely on.
"""

import numpy as np
import pytest

from models.gnn.subgraph import compiled, mesh, subgraph, subgraph_numpy
from stmpl import reach


@pytest.fixture(scope="module")
def arm_mesh(arm):
    e = arm.edges
    ei = np.concatenate([e, e[:, ::-1]]).T
    return mesh(arm, ei), ei


@pytest.mark.parametrize("grow", [0, 1])
def test_the_kernel_gives_the_numpy_subgraph(arm, arm_mesh, grow):
    if compiled() is False:
        pytest.skip("Numba is not installed")
    m, _ = arm_mesh
    rng = np.random.default_rng(0)
    seeds = np.zeros((3, arm.n_vertices), bool)
    seeds[0, rng.choice(arm.n_vertices, 4, replace=False)] = True
    seeds[1, 100:130] = True  # scene 2: nothing moves
    want = subgraph_numpy(m, arm, seeds, 3, grow)
    got = subgraph(m, arm, seeds, 3, grow)
    for a, b in zip(got, want):
        np.testing.assert_array_equal(a, b)
    assert got.sizes(3) == want.sizes(3)


def test_each_step_reads_only_nodes_and_edges_within_its_rings(arm, arm_mesh):
    m, ei = arm_mesh
    seeds = np.zeros((2, arm.n_vertices), bool)
    seeds[0, 50] = seeds[1, 400] = True
    g = subgraph(m, arm, seeds, 3, grow=1)
    N, E = arm.n_vertices, ei.shape[1]
    level = reach.hops(arm, reach.grown(arm, seeds, 1), 3).ravel()
    np.testing.assert_array_equal(np.sort(g.nodes), np.flatnonzero(level <= 3))
    assert (np.diff(level[g.nodes]) >= 0).all()  # nodes by level
    b, e = np.divmod(g.rows, E)
    np.testing.assert_array_equal(g.nodes[g.edges[0]], ei[0][e] + b * N)  # rows match edges
    np.testing.assert_array_equal(g.nodes[g.edges[1]], ei[1][e] + b * N)
    for s, (n, k) in enumerate(g.sizes(3), start=1):
        assert (g.edges[1, :k] < n).all()  # a step's edges point into the nodes it updates
        assert level[g.nodes[:n]].max() <= 3 - s  # ... which lie within the rings left
        assert (level[g.nodes[g.edges[1, :k]]] < 3 - s + 1).all()
    # every edge into a node under 3 rings is there, once
    into = np.flatnonzero(level[(ei[1][None] + N * np.arange(2)[:, None]).ravel()] < 3)
    assert len(g.rows) == len(into) == len(np.unique(g.rows))
