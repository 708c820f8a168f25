"""Ready-made objects (stmpl/contact/objects.py) and where they go."""

import numpy as np
import pytest

import stmpl.contact.pressing as C
from stmpl.body import tube
from stmpl.contact import objects


def test_shapes_are_closed_and_rest_on_z0():
    for m in (objects.sphere(0.008), objects.rod(0.005, 0.1), objects.letters("ECCV", 0.03)):
        assert m.is_watertight and m.volume > 0
        assert m.vertices[:, 2].min() == pytest.approx(0.0, abs=1e-9)
    assert objects.sphere(0.008).volume == pytest.approx(4 / 3 * np.pi * 0.008**3, rel=0.02)
    rod = objects.rod(0.005, 0.1)
    np.testing.assert_allclose(rod.bounds[1] - rod.bounds[0], [0.1, 0.01, 0.01], atol=1e-4)


def test_letters_have_their_holes():
    """An O is a ring: its extrusion's volume is the outline's area minus the hole's."""
    o = objects.letters("O", 0.03, 0.01)
    import shapely.geometry as geo

    from stmpl.loads import glyph_contours

    outer, inner = sorted((geo.Polygon(c * 0.03).area for c in glyph_contours("O")), reverse=True)
    assert o.volume == pytest.approx((outer - inner) * 0.01, rel=1e-6)
    eccv = objects.letters("ECCV", 0.03)
    assert len(eccv.split(only_watertight=False)) == 4
    with pytest.raises(ValueError, match="not in the letter font"):
        objects.letters("\u6f22")


def test_press_sets_the_lowest_point_depth_into_the_skin():
    t = tube(0.04, 0.2, 48, 40)
    tip = objects.sphere(0.01)
    k = 20 * 48 + 12  # a vertex half way along the tube
    pose = objects.press(t, tip, k, depth=0.003)
    c = C.contact(t, C.Pressing(tip, pose, 0.2), tolerance=0.0)
    assert c.penetration[k] == c.penetration.max() == pytest.approx(0.003, abs=1e-4)
    frame = objects.surface_frame(t, uv=(0.3, 0.5))
    np.testing.assert_allclose(frame[:3, :3] @ frame[:3, :3].T, np.eye(3), atol=1e-12)


def test_a_strap_squeezes_a_ring_of_the_limb():
    t = tube(0.04, 0.2, 24, 20)
    c = C.contact(t, objects.strap(t, at=0.5, width=0.03, squeeze=0.003))
    s = t.axial[c.vertices]
    assert abs(s.mean() - 0.1) < 0.006 and np.ptp(s) <= 0.03 + 2 * 0.002  # tolerance
    assert len(c.vertices) % 24 == 0  # whole rings around the tube
    assert c.penetration.max() == pytest.approx(0.003, abs=2e-4)
    with pytest.raises(ValueError, match="no limb axis"):
        from stmpl.body import sheet

        objects.strap(sheet())
    with pytest.raises(ValueError, match="under half the thickness"):
        objects.strap(t, squeeze=0.006, thickness=0.01)


def test_a_disk_presses_as_the_rounded_punch_of_the_closed_forms():
    """The disk mesh stands on its face at z = 0, closed and facing out, and seen along its
    press it is the rounded punch of :func:`stmpl.contact.gap.disk` within its facets.
    """
    from stmpl.contact import gap

    m = objects.disk(0.01, rounding=0.001)
    assert m.is_watertight and m.is_winding_consistent and m.volume > 0
    assert m.bounds[0][2] == pytest.approx(0.0) and m.bounds[1][2] == pytest.approx(0.01)
    rng = np.random.default_rng(0)
    x = np.column_stack([rng.uniform(-0.012, 0.012, (400, 2)), rng.uniform(-0.01, -0.001, 400)])
    down = np.array([0.0, 0.0, -1.0])  # it presses down: the points below lie ahead of it
    exact = gap.disk(x, [0.0, 0.0, 0.0], 0.01, down, rounding=0.001)
    meshed = gap.mesh(m, x, down)
    hit = exact < 0.02
    np.testing.assert_allclose(meshed[hit], exact[hit], atol=1e-4)  # 64 sections, 8 on the arc
    assert (meshed[~hit] >= 0.02 - 1e-12).all()
    with pytest.raises(ValueError, match="rounding must be >= 0 and below"):
        objects.disk(0.01, rounding=0.02)
