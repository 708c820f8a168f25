"""The closed forms the FEM is checked against, checked themselves."""

import numpy as np
import pytest

from fem.verification import (
    arm_tube,
    dimitriadis_force,
    graded,
    hayes_kappa,
    hertz_force,
    quarter_disk,
)

HAYES_045 = {0.2: 1.252, 0.4: 1.599, 0.6: 2.031, 0.8: 2.532, 1.0: 3.085, 1.5: 4.638, 2.0: 6.380}
"""Hayes et al. (1972)'s published kappa at nu = 0.45, as tabulated in the literature."""


@pytest.mark.parametrize("a_over_h", sorted(HAYES_045))
def test_hayes_kappa_solves_its_integral_equation_to_the_published_table(a_over_h):
    """Within 1 % of the published values (0.04 % at a/h <= 0.6, 0.6 % at a/h = 2)."""
    assert hayes_kappa(a_over_h, 0.45) == pytest.approx(HAYES_045[a_over_h], rel=0.01)


def test_hayes_kappa_tends_to_sneddons_half_space():
    assert hayes_kappa(0.01, 0.3) == pytest.approx(1.0, abs=0.01)
    assert hayes_kappa(1.0, 0.3) < hayes_kappa(1.0, 0.45) < hayes_kappa(1.0, 0.49)


def test_dimitriadis_tends_to_hertz_for_a_thick_incompressible_layer():
    E, R, d = 2000.0, 0.01, 1e-4
    assert dimitriadis_force(E, R, d, 1e3) == pytest.approx(hertz_force(E, 0.5, R, d), rel=1e-4)
    assert dimitriadis_force(E, R, d, 0.01) > 1.1 * hertz_force(E, 0.5, R, d)


def test_quarter_disk_rings_are_circles():
    radii = np.array([0.0, 0.001, 0.0025, 0.004])
    part = quarter_disk(radii)
    r = np.linalg.norm(part.vertices[:, :2], axis=1)
    assert np.all(np.min(np.abs(r[:, None] - radii[None]), axis=1) < 1e-12)
    assert part.vertices[:, :2].min() >= -1e-15
    assert part.vertex_areas.sum() == pytest.approx(np.pi / 4 * 0.004**2, rel=0.03)
    steps = graded(0.001, 0.01, 1.3)
    assert steps[0] == 0 and steps[-1] == 0.01 and np.all(np.diff(steps) > 0)


def test_the_arm_tube_presses_at_its_middle_along_its_outward_normal():
    part, thickness, point, normal = arm_tube()
    assert thickness.shape == (part.n_vertices,) and np.all(thickness == 0.0075)
    assert np.hypot(point[0], point[1]) == pytest.approx(0.035)
    assert abs(point[2] - 0.04) < 0.08 / 7  # the ring nearest the middle
    np.testing.assert_allclose(normal, point * [1, 1, 0] / 0.035, atol=1e-9)
