"""The volume part of the tissue laws and which elements take it on their mean volume ratio."""

import numpy as np
import pytest

from fem.material import NeoHookean, Yeoh
from fem.volume import NEARLY_INCOMPRESSIBLE, volume_split, volumetric


def test_the_volume_part_vanishes_at_rest_and_its_derivatives_are_its_slopes():
    K = np.full(5, 2e5)
    J = np.array([0.7, 0.9, 1.0, 1.1, 1.3])
    U, dU, d2U = volumetric(K, J)
    assert U[2] == 0.0 and dU[2] == 0.0 and d2U[2] == pytest.approx(K[2])  # U''(1) = K
    h = 1e-6
    for k in (0, 1):  # U' and U'' against central differences of U and U', Pa
        slope = (volumetric(K, J + h)[k] - volumetric(K, J - h)[k]) / (2 * h)
        np.testing.assert_allclose((dU, d2U)[k], slope, rtol=1e-6, atol=1e-3)
    assert volumetric(K[:1], np.array([0.0]))[0][0] == np.inf  # an inverted element


def test_only_a_nearly_incompressible_law_takes_its_volume_on_the_mean():
    mu = 1000.0  # Yeoh's C10 = mu / 2
    stiff = Yeoh(C10=mu / 2, K=2 * NEARLY_INCOMPRESSIBLE * mu)
    soft = Yeoh(C10=mu / 2, K=13 * mu)  # the skin's K / mu
    bulk, points = volume_split(stiff, 3)
    np.testing.assert_array_equal(bulk, np.full(3, stiff.K))
    np.testing.assert_array_equal(points, np.zeros(3))
    assert volume_split(soft, 3) is None  # its law as it stands
    bulk, points = volume_split(soft, 3, "mean")
    np.testing.assert_array_equal(bulk, np.full(3, soft.K))
    assert volume_split(NeoHookean(), 3) is None  # no separable volume term
    with pytest.raises(ValueError, match="mean dilatation needs laws with a bulk modulus"):
        volume_split(NeoHookean(), 3, "mean")
