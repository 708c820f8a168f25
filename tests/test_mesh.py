"""The arrays-only mesh answers what contact asks of an object as trimesh does: its triangles,
bounds, extents, area, whether it is closed, and its rigid placement.
"""

import numpy as np
import pytest
import trimesh

from stmpl.mesh import Mesh


def _pair(shape):
    return Mesh(shape.vertices, shape.faces), shape


@pytest.mark.parametrize(
    "shape",
    [
        trimesh.creation.icosphere(2, 0.01),
        trimesh.creation.box((0.02, 0.03, 0.01)),
        trimesh.creation.cylinder(0.01, 0.02, sections=24),
    ],
    ids=["ball", "box", "cylinder"],
)
def test_it_measures_a_shape_as_trimesh_does(shape):
    ours, theirs = _pair(shape)
    np.testing.assert_allclose(ours.triangles, theirs.triangles)
    np.testing.assert_allclose(ours.bounds, theirs.bounds)
    np.testing.assert_allclose(ours.extents, theirs.extents)
    assert ours.area == pytest.approx(theirs.area, rel=1e-12)
    assert ours.is_watertight and theirs.is_watertight


def test_an_open_or_badly_wound_surface_is_not_closed():
    ball = trimesh.creation.icosphere(1, 0.01)
    assert not Mesh(ball.vertices, ball.faces[1:]).is_watertight  # a hole
    flipped = ball.faces.copy()
    flipped[0] = flipped[0, ::-1]  # one face wound against its neighbours
    assert not Mesh(ball.vertices, flipped).is_watertight
    assert not Mesh(np.zeros((0, 3)), np.zeros((0, 3), int)).is_watertight


def test_a_rigid_move_moves_every_vertex_and_leaves_the_copy():
    ball = trimesh.creation.icosphere(1, 0.01)
    m = Mesh(ball.vertices, ball.faces)
    turn = trimesh.transformations.rotation_matrix(0.7, [0.2, 1.0, 0.3])
    turn[:3, 3] = [0.1, -0.2, 0.05]
    moved = m.copy().apply_transform(turn)
    np.testing.assert_allclose(moved.vertices, ball.copy().apply_transform(turn).vertices)
    np.testing.assert_allclose(m.vertices, ball.vertices)  # the original stays
    assert moved.area == pytest.approx(m.area)


def test_bad_arrays_are_refused_by_name():
    with pytest.raises(ValueError, match=r"\(V, 3\) vertices and \(F, 3\) faces"):
        Mesh(np.zeros((4, 2)), [[0, 1, 2]])
    with pytest.raises(ValueError, match="faces index vertices 0..2, got 0..3"):
        Mesh(np.zeros((3, 3)), [[0, 1, 3]])
