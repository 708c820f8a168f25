"""The inputs both networks take (models/features.py), against their closed forms."""

import numpy as np
import pytest
import torch

from models import features
from stmpl import tissue


def test_load_channels():
    force = torch.tensor([[0.0, 0.2, 0.3], [0.0, 0.0, 0.0]])
    inv_area = torch.tensor([1.0, 2.0, 4.0])
    (pressure,) = features.load_channels(force, inv_area, per_newton=False)
    np.testing.assert_allclose(pressure.numpy(), [[0, 0.4, 1.2], [0, 0, 0]], rtol=1e-6)
    pattern, total = features.load_channels(force, inv_area, per_newton=True)
    np.testing.assert_allclose(pattern.numpy(), [[0, 0.8, 2.4], [0, 0, 0]], rtol=1e-6)
    np.testing.assert_allclose(total.numpy(), [[0.5] * 3, [0.0] * 3], rtol=1e-6)
    assert torch.all(torch.isfinite(pattern))  # an unloaded scene: zeros, not NaN


def test_thickness_over_its_range():
    lo, hi = tissue.THICKNESS_RANGE
    t = torch.tensor([[lo, (lo + hi) / 2, hi]], dtype=torch.float32)
    np.testing.assert_allclose(features.normalised_thickness(t).numpy(), [[0, 0.5, 1]], atol=1e-6)
    assert features.normalised_thickness(t).dtype == torch.float32
    assert features.THICKNESS_SHIFT == lo and features.THICKNESS_SCALE == pytest.approx(hi - lo)


def test_pressures_are_read_from_their_logarithm_and_cannot_overflow():
    raw = torch.tensor([np.log(25.0), np.log(0.02), 0.0, 1e4])
    out = features.pressure_out(raw).numpy()
    np.testing.assert_allclose(out[:3], [25.0, 0.02, 1.0], rtol=1e-5)
    assert out[3] == pytest.approx(np.exp(features.PRESSURE_LOG_MAX), rel=1e-5)


def test_a_vertex_s_share_of_the_contact_force_tapers_to_none_past_the_band():
    band, taper = features.CONTACT_BAND, features.CONTACT_TAPER
    gap = np.array([-0.01, 0.0, band, band + taper / 4, band + taper / 2, band + taper, 0.05])
    want = [1.0, 1.0, 1.0, 0.75, 0.5, 0.0, 0.0]
    np.testing.assert_allclose(features.contact_weight(gap), want, atol=1e-12)
    np.testing.assert_allclose(features.contact_weight(torch.tensor(gap)).numpy(), want, atol=1e-12)
    # the regions reach every vertex with a share, and no other
    near = features.near_objects(gap)
    assert np.array_equal(near > 0, features.contact_weight(gap) > 0)
    assert np.array_equal(features.near_objects(torch.tensor(gap)).numpy(), near)


def test_a_posed_answer_s_contact_ends_where_its_pressure_falls_below_a_share_of_its_peak(arm):
    """The network's pressure never reaches zero; the answered contact (its force) has an edge
    at :data:`CONTACT_FLOOR` of the peak, as the FEM's has, while the reaction (from the push)
    keeps every vertex within the band.
    """
    from stmpl.pose import Pose
    from stmpl.scene import Scene

    n = arm.n_vertices
    gap = np.full(n, 0.001)  # every vertex within the band: a whole share each
    pressure = np.full(n, 1e3)  # 1 kPa far off ...
    pressure[:5] = 2e5  # ... 200 kPa under the object: 0.5 % of the peak
    pressure[5] = 2e5 * features.CONTACT_FLOOR  # just at the edge: kept
    scene = Scene.posed(arm, np.full(n, 0.008), Pose(gap, [0.0, 0.0, -1.0]))
    a = features.posed_answer(scene, np.zeros((n, 3)), pressure, np.full(n, 2.0))
    area = arm.vertex_areas
    np.testing.assert_allclose(a["force"][:5], 2e5 * area[:5])
    assert a["force"][5] == pytest.approx(2e3 * area[5]) and not a["force"][6:].any()
    assert a["reaction"] == pytest.approx(2.0 * area.sum())
