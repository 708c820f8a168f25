import numpy as np
import pytest

from stmpl.body import BodyPart, extract_part, sheet, tube
from stmpl.geometry import boundary_loops, project_on_polyline


def test_tube_geometry_matches_closed_form():
    p = tube(radius=0.04, length=0.3, n_around=48, n_along=31)
    # polygonal lateral area: n * (2 r sin(pi/n)) * length
    exact = 48 * 2 * 0.04 * np.sin(np.pi / 48) * 0.3
    assert p.face_areas.sum() == pytest.approx(exact, rel=1e-12)
    assert p.vertex_areas.sum() == pytest.approx(exact, rel=1e-12)
    assert len(p.seam_groups) == 31 and all(len(g) == 2 for g in p.seam_groups)
    assert [len(r) for r in p.rims] == [48, 48]
    assert p.axial.min() == pytest.approx(0) and p.axial.max() == pytest.approx(0.3)


def test_chart_is_normalised_with_aspect_kept():
    p = tube(radius=0.04, length=0.3, n_around=24, n_along=10)
    lo, hi = p.uv.min(0), p.uv.max(0)
    assert lo.min() == pytest.approx(0.04) and hi.max() == pytest.approx(0.96)
    # aspect: circumference / length
    assert (hi - lo)[0] / (hi - lo)[1] == pytest.approx(2 * np.pi * 0.04 / 0.3, rel=1e-9)
    # uv_scale * chart extent = true length along the tube
    assert (hi - lo)[1] * p.uv_scale == pytest.approx(0.3, rel=0.02)


def test_arrays_round_trip():
    p = tube(n_around=12, n_along=5)
    q = BodyPart.from_arrays(p.name, p.arrays(), p.source)
    for k in ("vertices", "faces", "normals", "uv", "face_uv", "uv_vertex", "axis"):
        np.testing.assert_array_equal(getattr(p, k), getattr(q, k))
    assert [r.tolist() for r in p.rims] == [r.tolist() for r in q.rims]


def test_extract_part_keeps_one_chart_and_one_piece():
    p = tube(n_around=16, n_along=11)
    mask = p.vertices[:, 2] <= 0.15 + 1e-9
    mask[-1] = True  # a stray vertex with no whole face is dropped
    q = extract_part("half", p.vertices, p.faces, p.uv, p.face_uv, mask)
    assert q.n_faces == 2 * 16 * 5
    assert q.n_vertices == 16 * 6
    assert len(q.rims) == 2


def test_boundary_loops_of_sheet_and_closed_surface():
    s = sheet(nx=5, ny=4)
    (loop,) = s.rims
    assert len(loop) == 2 * (5 + 4) - 4
    closed = np.array([[0, 1, 2], [0, 2, 3], [0, 3, 1], [1, 3, 2]])
    assert boundary_loops(closed) == ()


def test_project_on_polyline():
    line = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0]], float)
    pts = np.array([[0.5, 0.2, 0], [1.3, 0.5, 0], [-1, 0, 0]], float)
    np.testing.assert_allclose(project_on_polyline(pts, line), [0.5, 1.5, 0.0])


@pytest.mark.parametrize(
    "field,value,message",
    [
        ("vertices", np.zeros((4, 2)), "vertices must have shape"),
        ("faces", np.array([[0, 1, 99]]), "out of range"),
        ("normals", np.full((4, 3), np.nan), "non-finite"),
    ],
)
def test_bad_part_arrays_are_named(field, value, message):
    base = dict(
        name="x",
        vertices=np.eye(4, 3),
        faces=np.array([[0, 1, 2]]),
        normals=np.tile([0, 0, 1.0], (4, 1)),
        uv=np.eye(3, 2),
        face_uv=np.array([[0, 1, 2]]),
        uv_vertex=np.array([0, 1, 2]),
        uv_scale=1.0,
    )
    base[field] = value
    if field == "faces":
        base["face_uv"] = np.array([[0, 1, 2]])
    with pytest.raises(ValueError, match=message):
        BodyPart(**base)


def test_subdivision_keeps_the_surface_and_carries_uvs_seams_and_rims():
    from stmpl.body import tube

    t = tube(0.04, 0.2, 16, 12)
    f = t.subdivided(1)
    assert f.n_vertices == t.n_vertices + len(t.edges) and f.n_faces == 4 * t.n_faces
    assert f.face_areas.sum() == pytest.approx(t.face_areas.sum())
    np.testing.assert_array_equal(f.vertices[: t.n_vertices], t.vertices)
    assert len(f.seam_vertices) == 2 * len(t.seam_vertices) - 1  # the seam's midpoints too
    assert [len(r) for r in f.rims] == [2 * len(r) for r in t.rims]
    for r in f.rims:  # a rim is still a loop
        steps = np.linalg.norm(np.diff(f.vertices[np.r_[r, r[:1]]], axis=0), axis=1)
        assert steps.max() < 0.6 * 2 * np.pi * 0.04 / 16
    # a linear field in 3D is linear in the chart: UVs interpolate like positions
    mid = f.uv_vertex >= t.n_vertices
    np.testing.assert_allclose(np.linalg.norm(f.normals, axis=1), 1.0)
    assert mid.sum() > 0 and f.source["subdivisions"] == 1
    assert np.all(np.abs(f.uv[mid] - 0.5) <= 0.5)


def test_finer_anny_arm(arm):
    from stmpl.body.spec import part_from_spec

    fine = part_from_spec({"model": "anny", "subdivisions": 1}, "left_arm")
    assert fine.n_vertices == arm.n_vertices + len(arm.edges)
    assert fine.source["subdivisions"] == 1 and fine.name == "left_arm"
    with pytest.raises(ValueError, match="subdivisions must be an integer 0..3"):
        part_from_spec({"model": "anny", "subdivisions": 9}, "left_arm")


def test_a_subdivided_part_read_back_knows_the_part_it_came_from(arm):
    """Saved and read again (a scene file, a dataset), a subdivided part rebuilds its coarser
    part from its own arrays, so a press on it is meshed there (fem.finer); a part that only
    claims a subdivision, or was edited since, does not.
    """
    from stmpl.body.spec import part_from_spec

    fine = part_from_spec({"model": "anny", "subdivisions": 2}, "left_arm")
    back = BodyPart.from_arrays(fine.name, fine.arrays(), fine.source)
    for got, want in ((back.coarser, fine.coarser), (back.coarser.coarser, arm)):
        for k in ("vertices", "faces", "normals", "uv", "face_uv", "uv_vertex", "body_index"):
            np.testing.assert_array_equal(getattr(got, k), getattr(want, k))
        assert [r.tolist() for r in got.rims] == [r.tolist() for r in want.rims]
    assert back.coarser.source == fine.coarser.source and back.coarser.coarser.coarser is None
    assert BodyPart.from_arrays(arm.name, arm.arrays(), arm.source).coarser is None
    claims = {**arm.source, "subdivisions": 1}
    assert BodyPart.from_arrays(arm.name, arm.arrays(), claims).coarser is None
    moved = fine.coarser.arrays()  # one edge's midpoint moved off its edge
    moved["vertices"] = moved["vertices"].copy()
    moved["vertices"][-1] += [1e-4, 0, 0]
    assert BodyPart.from_arrays(arm.name, moved, fine.coarser.source).coarser is None


def test_rim_distance_is_zero_on_the_rims_and_half_the_length_midway():
    from stmpl.body.primitives import tube

    part = tube(radius=0.04, length=0.2, n_around=16, n_along=12)
    d = part.rim_distance
    assert np.all(d[np.concatenate(part.rims)] == 0)
    z = part.vertices[:, 2]
    mid = np.argmin(np.abs(z - z.mean()))
    assert d[mid] == pytest.approx(0.1, abs=0.01)
