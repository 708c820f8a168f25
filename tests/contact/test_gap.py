"""The gap along a press (stmpl/contact/gap.py): closed forms of a ball and a rounded disk,
and a mesh's rays against them.
"""

import numpy as np
import pytest
import trimesh

from stmpl.contact import gap
from stmpl.pose import GAP_REACH

D = np.array([0.0, 0.0, -1.0])  # pressing down


def test_under_a_disk_s_face_the_gap_is_its_depth_however_deep():
    """A 10 mm disk, rim rounded 1 mm, its face 6 mm below the skin plane z = 0: every vertex
    under the face lies 6 mm inside (where the signed distance would be at most the distance
    to the side), the rim's quarter circle rises to the face's edge, and off the disk nothing.
    """
    x = np.array([[r, 0.0, 0.0] for r in (0.0, 0.0085, 0.009, 0.0095, 0.0099, 0.0101, 0.03)])
    g = gap.disk(x, [0.0, 0.0, -0.006], 0.01, D, rounding=0.001)
    rise = 0.001 - np.sqrt(0.001**2 - (x[2:5, 0] - 0.009) ** 2)  # the rim, above the face
    np.testing.assert_allclose(g[:2], -0.006, atol=1e-12)
    np.testing.assert_allclose(g[2:5], -0.006 + rise, atol=1e-12)
    assert g[4] > g[3] > g[2] and (g[5:] == GAP_REACH).all()
    ahead = gap.disk([[0.0, 0.0, -0.009]], [0.0, 0.0, -0.006], 0.01, D)  # 3 mm ahead of it
    assert ahead[0] == pytest.approx(0.003)


def test_a_ball_s_rays_match_its_closed_form_and_a_mesh_s_too():
    """A ball of 8 mm pressed along a slanted direction: the closed form's gap at points on
    and off its track, and the rays cast at an icosphere of it agree within its facets.
    """
    d = np.array([0.3, -0.2, -1.0]) / np.linalg.norm([0.3, -0.2, -1.0])
    centre = np.array([0.001, 0.002, 0.004])
    rng = np.random.default_rng(0)
    x = rng.uniform([-0.015, -0.015, -0.006], [0.015, 0.015, 0.002], size=(500, 3))
    exact = gap.ball(x, centre, 0.008, d)
    rel = x - centre
    along = rel @ d
    rho = np.linalg.norm(rel - along[:, None] * d, axis=1)
    on = rho < 0.008
    np.testing.assert_allclose(
        exact[on], np.minimum(along - np.sqrt(0.008**2 - rho**2), GAP_REACH)[on]
    )
    assert (exact[~on] == GAP_REACH).all() and (exact[on] < 0).any()
    mesh = trimesh.creation.icosphere(subdivisions=4, radius=0.008)
    mesh.apply_translation(centre)
    rays = gap.mesh(mesh, x, d)
    inner = rho < 0.0075  # off the ball's silhouette, where a facet moves the front little
    np.testing.assert_allclose(rays[inner], exact[inner], atol=1e-4)
    assert (rays[rho > 0.0082] == GAP_REACH).all()


def test_a_sample_s_gap_is_measured_along_its_press_and_a_grip_s_is_kept():
    x = np.array([[0.0, 0.0, 0.0], [0.05, 0.0, 0.0]])
    params = {"centre": [0.0, 0.0, -0.004], "radius": 0.01, "rounding": 0.001, "direction": D}
    g = gap.of_sample(x, "press_disk", params, stored=[-0.001, 0.012])
    np.testing.assert_allclose(g, [-0.004, 0.012])  # inside along the press, outside signed
    kept = gap.of_sample(x, "press_grip", {"direction": None}, stored=[-0.001, 0.5])
    np.testing.assert_allclose(kept, [-0.001, GAP_REACH])
    with pytest.raises(ValueError, match="does not record its object's pose"):
        gap.of_press(x, "press_sphere", {"radius": 0.008})
    with pytest.raises(ValueError, match="finite nonzero 3-vector"):
        gap.ball(x, [0, 0, 0], 0.008, [0, 0, 0])


def test_the_way_field_is_the_press_direction_or_the_nearest_object_vertices_paths():
    """Within reach of an object the way is the press direction; a closing pose's is the paths
    of the object vertices nearest each point (two fingers sweeping opposite ways drag the skin
    under each its own way); beyond reach it is zero; a closing pose without paths is refused.
    """
    from stmpl.pose import Rigid

    x = np.array([[-0.01, 0.0, 0.0], [0.01, 0.0, 0.0], [0.5, 0.0, 0.0]])
    g = np.array([-0.001, 0.002, GAP_REACH])
    w = gap.way(x, g, [0.0, 0.0, -2.0])
    np.testing.assert_allclose(w, [[0, 0, -1], [0, 0, -1], [0, 0, 0]])
    tri = np.array([[0, 1, 2]])
    left = Rigid(
        "left",
        [[-0.01, 0, 0.001], [-0.012, 0, 0.001], [-0.01, 0.002, 0.001]],
        tri,
        path=np.tile([0.0, 0.8, -0.6], (3, 1)),
    )
    right = Rigid(
        "right",
        [[0.01, 0, 0.001], [0.012, 0, 0.001], [0.01, 0.002, 0.001]],
        tri,
        path=np.tile([0.0, -0.8, -0.6], (3, 1)),
    )
    w = gap.way(x, g, None, (left, right))
    np.testing.assert_allclose(w, [[0, 0.8, -0.6], [0, -0.8, -0.6], [0, 0, 0]])
    with pytest.raises(ValueError, match="needs its objects, each with its path"):
        gap.way(x, g, None, (Rigid("box", left.vertices, tri),))
    with pytest.raises(ValueError, match="one distance per point"):
        gap.way(x, g[:2], D)


def test_a_closing_pose_s_way_blends_the_nearest_paths_and_changes_continuously():
    """Four object vertices on a line, each closing its own way: a point's way weights the
    paths of its three nearest by how much nearer each is than the fourth (worked by hand at
    x = 0.4); walked across the object the way changes by at most a step's worth (the nearest
    vertex's path alone jumps by its full difference where two are equally near); a point
    equidistant from all four takes their mean; of three vertices, the two nearest blend.
    """
    from stmpl.pose import Rigid

    v = np.array([[0.0, 0, 0], [1.0, 0, 0], [2.0, 0, 0], [3.0, 0, 0]])
    path = np.array([[1.0, 0, 0], [0.0, 1, 0], [0.0, 0, 1], [1.0, 1, 1]])
    line = Rigid("line", v, np.array([[0, 1, 2], [1, 2, 3]]), path=path)
    x = np.array([[0.4, 0.0, 0.0]])
    w = gap.way(x, [-0.001], None, (line,))
    d = np.array([0.4, 0.6, 1.6, 2.6])  # the distances to the four, nearest first
    expected = ((d[3] - d[0]) * path[0] + (d[3] - d[1]) * path[1] + (d[3] - d[2]) * path[2]) / (
        3 * d[3] - d[:3].sum()
    )
    np.testing.assert_allclose(w[0], expected)
    walk = np.stack([np.linspace(-0.5, 3.5, 4001), np.zeros(4001), np.zeros(4001)], 1)
    ways = gap.way(walk, np.full(4001, -0.001), None, (line,))
    step = np.linalg.norm(np.diff(ways, axis=0), axis=1).max()
    assert step < 0.01, step  # a step of 1 mm of the 4 m walk: no jump
    single = np.linalg.norm(np.diff(path[[0, 1]], axis=0))
    assert single > 1.0  # what the nearest vertex's path alone would jump by at x = 0.5
    square = Rigid(
        "square",
        [[1.0, 0, 0], [-1.0, 0, 0], [0, 1.0, 0], [0, -1.0, 0]],
        np.array([[0, 1, 2], [0, 1, 3]]),
        path=path,
    )
    np.testing.assert_allclose(gap.way([[0, 0, 0.0]], [-0.001], None, (square,))[0], path.mean(0))
    tri = Rigid("tri", v[:3], np.array([[0, 1, 2]]), path=path[:3])  # fewer than four
    d = np.array([0.4, 0.6, 1.6])
    expected = ((d[2] - d[0]) * path[0] + (d[2] - d[1]) * path[1]) / (2 * d[2] - d[:2].sum())
    np.testing.assert_allclose(gap.way(x, [-0.001], None, (tri,))[0], expected)
