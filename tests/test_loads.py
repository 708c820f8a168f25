import numpy as np
import pytest

from stmpl import loads
from stmpl.body import sheet, tube


@pytest.fixture(scope="module")
def plate():
    return sheet(0.2, 0.2, 81, 81)  # 2.5 mm spacing


def test_disk_area_force_and_pressure(plate):
    ld = loads.disk(plate, [0.0, 0.0, 0.0], radius=0.0201, total=3.0)
    assert ld.area == pytest.approx(np.pi * 0.0201**2, rel=0.05)
    np.testing.assert_allclose(ld.force[ld.vertices], 3.0 / ld.count)
    assert ld.force.sum() == pytest.approx(3.0)
    assert np.count_nonzero(ld.force) == ld.count
    assert ld.pressure == pytest.approx(3.0 / ld.area)
    inside = np.linalg.norm(plate.vertices, axis=1) <= 0.0201
    np.testing.assert_array_equal(np.sort(ld.vertices), np.nonzero(inside)[0])


def test_ellipse_matches_its_equation(plate):
    a, b, ang = 0.03, 0.012, 0.4
    ld = loads.ellipse(plate, [0.0, 0.0, 0.0], (a, b), ang, total=1.0)
    c, s = np.cos(ang), np.sin(ang)
    x, y = plate.vertices[:, 0], plate.vertices[:, 1]  # chart u is +x on the sheet
    xr, yr = c * x + s * y, -s * x + c * y
    expect = np.nonzero((xr / a) ** 2 + (yr / b) ** 2 <= 1)[0]
    np.testing.assert_array_equal(np.sort(ld.vertices), expect)
    assert ld.area == pytest.approx(np.pi * a * b, rel=0.06)


def test_disk_and_seam_disk_cross_the_seam_unbroken():
    p = tube(0.04, 0.3, 48, 61)
    ld = loads.seam_disk(p, at=0.5, radius=0.0151, total=2.0)
    centre = p.vertices[ld.params["seam_vertex"]]
    assert centre[2] == pytest.approx(0.15)
    th = np.arctan2(p.vertices[:, 1], p.vertices[:, 0])
    true = np.hypot(0.04 * np.abs(th), p.vertices[:, 2] - centre[2])
    np.testing.assert_array_equal(np.sort(ld.vertices), np.nonzero(true <= 0.0151)[0])
    side = np.sign(p.vertices[ld.vertices, 1])
    assert (side > 0).any() and (side < 0).any()  # both sides of the seam


def test_band_on_a_tube():
    p = tube(0.04, 0.3, 24, 31)
    ld = loads.band(p, at=0.5, width=0.03, total=4.0)
    expect = np.nonzero(np.abs(p.vertices[:, 2] - 0.15) <= 0.015 + 1e-12)[0]
    np.testing.assert_array_equal(ld.vertices, expect)


def test_letters_on_the_arm(arm):
    a = loads.letter(arm, "A", (0.5, 0.5), height=0.12, stroke=0.012, total=5.0)
    i = loads.letter(arm, "I", (0.5, 0.5), height=0.12, stroke=0.012, total=5.0)
    assert a.count > i.count > 0
    assert not np.array_equal(a.vertices, i.vertices)
    assert a.force.sum() == pytest.approx(5.0)


def test_arm_primitives_report_sensible_contact(arm):
    for ld in (
        loads.disk(arm, uv=(0.5, 0.5), radius=0.025, total=5),
        loads.ellipse(arm, uv=(0.3, 0.5), semi_axes=(0.04, 0.02), total=3),
        loads.seam_disk(arm, 0.5, 0.025, 2),
        loads.band(arm, 0.3, 0.03, 4),
    ):
        assert ld.count >= 3
        assert 0.3 < ld.area / (ld.count * arm.vertex_areas.mean()) < 3
    band = loads.band(arm, 0.5, 0.03, 4)
    circumference = band.area / 0.03
    assert 0.15 < circumference < 0.40  # a human upper/lower arm, m


def test_combine_adds_forces(plate):
    a = loads.disk(plate, [0.05, 0, 0], 0.01, 1.0)
    b = loads.disk(plate, [-0.05, 0, 0], 0.01, 2.0)
    c = loads.combine(plate, a, b)
    assert c.total == 3.0 and c.count == a.count + b.count
    np.testing.assert_allclose(c.force, a.force + b.force)


@pytest.mark.parametrize(
    "call,message",
    [
        (lambda p: loads.disk(p, [0, 0, 0], 0.02, -1.0), "total force must be finite and > 0"),
        (lambda p: loads.disk(p, [0, 0, 0], 0.02, np.nan), "total force must be finite"),
        (lambda p: loads.disk(p, [0, 0, 0], 0.0, 1.0), "radius must be finite and > 0"),
        (lambda p: loads.disk(p, [0, 0, 0.1], 0.02, 1.0), "mm off part"),
        (lambda p: loads.disk(p, [0.00125, 0.00125, 0], 0.0001, 1.0), "touches no vertex"),
        (lambda p: loads.disk(p, [0, 0, 0], 0.003, 200.0), "per-vertex force must be <= 20"),
        (lambda p: loads.disk(p, 0, 0.01, 1.0, uv=(0.5, 0.5)), "exactly one"),
        (lambda p: loads.ellipse(p, [0, 0, 0], (0.02, -1), 0, 1.0), "semi-axis b"),
        (lambda p: loads.seam_disk(p), "no UV seam"),
        (lambda p: loads.band(p), "no limb axis"),
        (lambda p: loads.letter(p, "AB"), "one visible character"),
        (lambda p: loads.letter(p, "A", uv=(2, 2)), "off the chart"),
        (lambda p: loads.letter(p, "\u6f22"), "not in the letter font"),  # a glyph it lacks
        (lambda p: loads.disk(p, [0, 0, 0], 1.0, 1.0), "covers the whole part"),
        (lambda p: loads.ellipse(p, [0, 0, 0], (1.0, 0.9), 0, 1.0), "covers the whole part"),
    ],
)
def test_bad_loads_are_named(plate, call, message):
    with pytest.raises(ValueError, match=message):
        call(plate)


def test_a_load_stays_on_its_part(plate):
    """A load remembers the mesh it was built on: a scene or a sum on another mesh of the same
    size refuses it instead of pressing the wrong vertices.
    """
    from stmpl.scene import Scene

    other = sheet(0.2, 0.2, 81, 81).with_vertices(plate.vertices * 1.5)
    ld = loads.disk(plate, [0, 0, 0], 0.02, 1.0)
    assert ld.part_id == plate.fingerprint != other.fingerprint
    with pytest.raises(ValueError, match="built on another part"):
        Scene.from_load(other, np.full(other.n_vertices, 0.005), ld)
    with pytest.raises(ValueError, match="load 0 .* another part"):
        loads.combine(other, ld)
    assert Scene.from_load(plate, np.full(plate.n_vertices, 0.005), ld).total_force == 1.0


def test_spots_are_small_disks_spread_around_a_centre(plate):
    """Each spot is the disk of its centre; the centres lie within the spread, evenly apart;
    the total is split equally over every touched vertex.
    """
    r, spread, h = 0.005, 0.03, 0.0025
    ld = loads.spots(plate, [0.0, 0.0, 0.0], count=3, radius=r, spread=spread, total=3.0)
    c = np.array(ld.params["centres"])
    assert c.shape == (3, 3) and np.allclose(c[0], 0.0)
    dist = np.linalg.norm(c[:, None] - c[None], axis=-1)[np.triu_indices(3, 1)]
    assert dist.min() >= spread - h and np.linalg.norm(c, axis=1).max() <= spread + 1e-9
    union = np.unique(np.concatenate([loads.disk(plate, x, r).vertices for x in c]))
    np.testing.assert_array_equal(np.sort(ld.vertices), union)
    np.testing.assert_allclose(ld.force[ld.vertices], 3.0 / ld.count)
    assert ld.area == pytest.approx(3 * np.pi * r**2, rel=0.15)
    one = loads.spots(plate, [0.0, 0.0, 0.0], count=1, radius=r, total=1.0)
    np.testing.assert_array_equal(one.vertices, loads.disk(plate, [0, 0, 0], r).vertices)
    for bad, msg in (
        ({"count": 0}, "count must be an integer >= 1"),
        ({"count": 2.5}, "count must be an integer"),
        ({"spread": 0.0}, "spread must be finite and > 0"),
        ({"count": 6, "spread": 0.003}, "widen the spread"),
    ):
        with pytest.raises(ValueError, match=msg):
            loads.spots(plate, [0.0, 0.0, 0.0], **{"radius": r, **bad})
