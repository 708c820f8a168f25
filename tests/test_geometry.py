"""Plain functions over triangle meshes."""

import numpy as np
import pytest

from stmpl.contact import objects
from stmpl.geometry import closest_points


@pytest.mark.parametrize("scale", [1.0, 1e-3])
def test_closest_points_on_triangles_at_any_scale(scale):
    """Against a dense sampling of each triangle (the nearest sample is never closer), at a
    metre's scale and a millimetre's.
    """
    rng = np.random.default_rng(2)
    tri = scale * rng.normal(size=(300, 3, 3))
    x = scale * rng.normal(size=(300, 3))
    c, w = closest_points(tri, x)
    np.testing.assert_allclose(np.einsum("kj,kji->ki", w, tri), c, atol=1e-12 * scale)
    assert w.min() >= 0 and np.allclose(w.sum(1), 1)
    s = np.linspace(0, 1, 60)
    a, b = np.meshgrid(s, s)
    keep = a + b <= 1
    bary = np.stack([1 - a[keep] - b[keep], a[keep], b[keep]], 1)  # (S, 3)
    samples = np.einsum("sj,kji->ksi", bary, tri)
    sampled = np.linalg.norm(samples - x[:, None], axis=2).min(1)
    found = np.linalg.norm(c - x, axis=1)
    assert np.all(found <= sampled + 1e-12 * scale)


def test_a_point_near_a_millimetre_sphere_is_as_far_from_its_mesh_as_from_the_sphere():
    """A point 0.075 mm outside a 10 mm icosphere (edges 0.8 mm, facets 9 um deep): its distance
    to the nearest triangle is the sphere's own within the facets, where the closest point of
    a library with absolute tolerances read 0.18 mm.
    """
    ball = objects.sphere(0.01, subdivisions=4)
    x = np.random.default_rng(0).uniform(-0.02, 0.04, size=(400, 3))
    exact = np.linalg.norm(x - [0, 0, 0.01], axis=1) - 0.01
    k = int(np.argmin(np.abs(exact - 7.544e-5)))
    tri = np.asarray(ball.triangles)
    c, _ = closest_points(tri, np.repeat(x[k][None], len(tri), 0))
    assert np.linalg.norm(c - x[k], axis=1).min() == pytest.approx(exact[k], abs=1.2e-5)
