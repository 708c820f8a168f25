import numpy as np
import pytest

from stmpl import surface
from stmpl.body import sheet, tube


def test_geodesics_on_a_plane_are_euclidean():
    p = sheet(0.2, 0.2, 41, 41)
    src = surface.closest_point(p, [0.011, -0.004, 0.002])
    assert src.position[2] == pytest.approx(0.0)
    d = surface.geodesic_distance(p, src)
    true = np.linalg.norm(p.vertices - src.position, axis=1)
    near = true < 0.04
    np.testing.assert_allclose(d[near], true[near], atol=1e-9)
    far = true < 0.09
    # beyond the local zone the heat method: about 6 % off here (near the sheet's free edge)
    assert np.abs(d - true)[far].max() < 0.07 * 0.09


def test_geodesics_around_a_cylinder():
    p = tube(0.04, 0.3, 48, 61)
    src = surface.vertex_point(p, 30 * 48)  # z = 0.15, angle 0
    d = surface.geodesic_distance(p, src)
    th = np.arctan2(p.vertices[:, 1], p.vertices[:, 0])
    true = np.hypot(0.04 * np.abs(th), p.vertices[:, 2] - 0.15)
    near = true < 0.04
    # the normal-angle arc is exact around and along; on helical paths it is within 1.5 %
    assert np.abs(d - true)[near].max() < 0.015 * 0.04
    ring = np.arange(30 * 48, 31 * 48)
    # halfway round: pi r, reached by the heat method
    assert d[ring].max() == pytest.approx(np.pi * 0.04, rel=0.05)


def test_tangent_frame_and_log_map():
    p = tube(0.04, 0.3, 48, 61)
    src = surface.vertex_point(p, 30 * 48 + 3)
    f = surface.tangent_frame(p, src)
    np.testing.assert_allclose(f @ f.T, np.eye(3), atol=1e-9)
    np.testing.assert_allclose(f[2], p.normals[30 * 48 + 3], atol=1e-2)
    xy = surface.log_map(p, src, surface.geodesic_distance(p, src))
    # along the tube (v, i.e. t2) and around it (u, t1)
    assert np.linalg.norm(xy[31 * 48 + 3] - [0, 0.005]) < 1e-3
    assert np.linalg.norm(xy[30 * 48 + 4] - [0.04 * 2 * np.pi / 48, 0]) < 1e-4


def test_points_off_the_part_are_refused():
    p = sheet()
    with pytest.raises(ValueError, match="mm off part 'sheet'"):
        surface.closest_point(p, [0, 0, 0.05])
    with pytest.raises(ValueError, match="off the chart"):
        surface.point_at_uv(p, [1.5, 0.5])
    with pytest.raises(ValueError, match="not in part"):
        surface.vertex_point(p, 10_000)
    with pytest.raises(ValueError, match="3 finite"):
        surface.closest_point(p, [np.nan, 0, 0])
