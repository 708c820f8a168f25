"""The contact wing's objects as the FEM's shapes: a posed mesh keeps its pose, and anny's hand
closes in a grip from first touch.
"""

import numpy as np
import pytest
import trimesh

from fem.objects import closing, surface
from stmpl.body import tube
from stmpl.contact.closing import closing_grip
from stmpl.contact.hand import Hand, SkinDistance
from stmpl.contact.pressing import Pressing, pose_matrix


def test_a_posed_mesh_is_the_same_object_in_body_coordinates():
    box = trimesh.creation.box(extents=(0.02, 0.02, 0.02))
    pressing = Pressing(box, pose_matrix((0.0, 0.0, 0.05)), 2.0, "cube")
    shape = surface(pressing, rounding=0.0)
    phi, grad, _ = shape.distance(np.array([[0.0, 0.0, 0.063], [0.0, 0.0, 0.05]]))
    np.testing.assert_allclose(phi, [0.003, -0.01], atol=1e-12)
    np.testing.assert_allclose(grad[0], [0, 0, 1], atol=1e-12)
    assert shape.name == "cube" and shape.path is None


@pytest.fixture(scope="module")
def limb():
    return tube(0.035, 0.25, 48, 60)


def test_a_grip_closes_from_first_touch(limb):
    """At depth 0 the hand touches the limb (clear of it by less than 0.1 mm); closed 3 mm
    further, it lies about 3 mm inside (the fingers move 1-1.5 mm per mm of the path).
    """
    hand = Hand()
    shape = closing(closing_grip(limb, hand, along=0.5, kind="pinch", reach=0.006))
    skin = SkinDistance(limb)
    first = skin(shape.pushed(0.0, None).vertices)
    assert 0 <= first.min() < 1e-4
    deeper = skin(shape.pushed(0.003, None).vertices)
    assert -0.0045 < deeper.min() < -0.0025
    for finger in ("thumb", "index"):
        assert skin(shape.pushed(0.003, None).vertices[hand.finger_of[finger]]).min() < 0
    with pytest.raises(ValueError, match="reach must lie in"):
        closing_grip(limb, hand, reach=0.02)
