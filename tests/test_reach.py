"""How far a load reaches: rings of mesh neighbours."""

import numpy as np

from stmpl import reach


def _rings_by_products(part, mask, steps):
    """The same levels by repeated products with the adjacency matrix (the plain definition)."""
    a = part.adjacency.astype(np.float32)
    level = np.where(mask, 0, steps + 1)
    sub = mask.copy()
    for k in range(1, steps + 1):
        wider = sub | (a @ sub.T.astype(np.float32) > 0).T
        level[wider & ~sub] = k
        sub = wider
    return level


def test_hops_count_rings_of_neighbours_per_scene(arm):
    rng = np.random.default_rng(0)
    mask = np.zeros((3, arm.n_vertices), bool)
    mask[0, rng.choice(arm.n_vertices, 5, replace=False)] = True  # scattered seeds
    mask[1, :40] = True  # a block
    # scene 2 has no seed: nothing is reached
    level = reach.hops(arm, mask, 4)
    np.testing.assert_array_equal(level, _rings_by_products(arm, mask, 4))
    assert (level[2] == 5).all() and (level[0] == 0).sum() == 5
    assert set(np.unique(level[0])) == {0, 1, 2, 3, 4, 5}
    np.testing.assert_array_equal(reach.grown(arm, mask, 2), level <= 2)
    one = reach.hops(arm, mask[1], 3)  # a single mask keeps its shape
    assert one.shape == (arm.n_vertices,)
    np.testing.assert_array_equal(one, np.minimum(level[1], 4))  # 4: beyond three rings
