"""From the page's choice to a scene: the objects press where they are put, with the force
given, and a bad choice is named.
"""

import numpy as np
import pytest

from stmpl import tissue
from stmpl.contact.hand import limb_point
from stmpl.viewer.press import Choice, along_around, pressed


def test_a_disk_and_a_fingertip_press_at_the_vertex_with_the_force(arm):
    t = tissue.constant(arm, 0.0075)
    v = int(np.argmin(np.linalg.norm(arm.vertices - arm.vertices.mean(0), axis=1)))
    for kind, radius in (("disk", 20.0), ("fingertip", 8.0)):
        scene, meshes = pressed(arm, t, Choice(kind, v, 0.4, radius))
        assert scene.force.sum() == pytest.approx(0.4)
        loaded = np.flatnonzero(scene.force > 0)
        assert np.linalg.norm(arm.vertices[loaded].mean(0) - arm.vertices[v]) < radius * 1e-3
        assert len(meshes) == 1 and np.isfinite(meshes[0].vertices).all()


def test_where_a_vertex_lies_on_the_limb_is_where_the_hand_would_grasp(arm):
    for along, around in ((0.3, 0.0), (0.5, 1.0), (0.7, -2.0)):
        point, _, _ = limb_point(arm, along, around)
        v = int(np.argmin(np.linalg.norm(arm.vertices - point, axis=1)))
        back, _, _ = limb_point(arm, *along_around(arm, v))
        assert np.linalg.norm(back - arm.vertices[v]) < 0.01  # within an edge of the coarse arm


def test_a_bad_choice_is_named(arm):
    with pytest.raises(ValueError, match="object must be one of"):
        Choice("anvil")
    with pytest.raises(ValueError, match="force must be above 0 N"):
        Choice(force=float("nan"))
    with pytest.raises(ValueError, match="upload a mesh"):
        Choice("mesh")
    with pytest.raises(ValueError, match="is not on the"):
        pressed(arm, tissue.constant(arm, 0.0075), Choice(vertex=10**6))
