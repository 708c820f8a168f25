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
