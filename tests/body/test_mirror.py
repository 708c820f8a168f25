"""The body's mirror (stmpl/body/mirror.py)."""

import numpy as np


def test_anny_arms_are_mirror_twins(anny_body):
    """Anny's right arm is its left arm in the mirror, vertex for vertex, on any body: so a
    model of one side can serve the other (``mirror_twin``); other parts are no twins.
    """
    from stmpl.body import AnnyBody
    from stmpl.body.mirror import MIRROR, mirror_twin

    left, right = anny_body.part("left_arm"), anny_body.part("right_arm")
    twin = mirror_twin(right, left)
    assert twin is not None and twin.name == "left_arm"
    np.testing.assert_allclose(twin.vertices, left.vertices, atol=1e-9)
    np.testing.assert_allclose(twin.normals, left.normals, atol=1e-9)
    assert twin.source["mirrored_from"] == "right_arm"
    other = AnnyBody(phenotype={"weight": 0.9, "height": 0.2})
    twin = mirror_twin(other.part("right_arm"), left)  # another body: its own shape
    np.testing.assert_allclose(twin.vertices, other.part("left_arm").vertices, atol=1e-9)
    np.testing.assert_allclose(twin.vertices * MIRROR, other.part("right_arm").vertices)
    assert mirror_twin(left, left) is None and mirror_twin(anny_body.part("belly"), left) is None


def symmetric_sheet():
    """A 21 x 5 sheet about x = 0 whose cells are cut along diagonals that mirror each other."""
    import dataclasses

    from stmpl.body.primitives import sheet

    s = sheet(0.2, 0.04, 21, 5)
    nx, faces = 21, []
    for i in range(4):
        for j in range(20):
            a = i * nx + j
            if j < 10:
                faces += [[a, a + 1, a + nx + 1], [a, a + nx + 1, a + nx]]
            else:
                faces += [[a, a + 1, a + nx], [a + 1, a + nx + 1, a + nx]]
    faces = np.array(faces)
    return dataclasses.replace(s, faces=faces, face_uv=faces)


def test_a_part_that_is_its_own_mirror_image_knows_each_vertex_s_twin(anny_body):
    """Anny's belly is its own mirror image, vertex for vertex and triangle for triangle: the
    twin map is a pairing (its own inverse) that sends each vertex to its mirror image. A limb is
    not, nor is a mesh whose vertices are symmetric but whose triangles are cut one way.
    """
    from stmpl.body.mirror import MIRROR, self_mirror
    from stmpl.body.primitives import sheet

    belly = anny_body.part("belly")
    twin = self_mirror(belly)
    assert twin is not None and (twin[twin] == np.arange(belly.n_vertices)).all()
    np.testing.assert_allclose(belly.vertices[twin], belly.vertices * MIRROR, atol=1e-9)
    assert (twin != np.arange(belly.n_vertices)).sum() > 0.9 * belly.n_vertices
    assert self_mirror(anny_body.part("left_arm")) is None
    assert self_mirror(sheet(0.2, 0.04, 21, 5)) is None  # every cell cut along one diagonal
    twin = self_mirror(symmetric_sheet())
    assert twin is not None and twin[0] == 20 and twin[10] == 10
