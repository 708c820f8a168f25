"""Contact from object meshes (stmpl/contact/pressing.py), against closed forms on a flat sheet."""

import numpy as np
import pytest
import trimesh

import stmpl.contact.pressing as C
from stmpl.body import sheet
from stmpl.contact import objects
from stmpl.geometry import closest_points
from stmpl.scene import Scene


@pytest.fixture(scope="module")
def plate():
    return sheet(0.2, 0.2, 81, 81)  # 2.5 mm spacing, z = 0, normal +z


def _tip(plate, depth=0.002, radius=0.01, at=(0.0, 0.0, 0.0), total=0.3):
    tip = objects.sphere(radius)
    return C.Pressing(tip, objects.press(plate, tip, list(at), depth=depth), total, "tip")


def test_a_sphere_touches_its_cap(plate):
    """A sphere of radius r pressed d deep touches the disk of radius sqrt(2 r d - d^2) and its
    deepest vertex lies d inside it.
    """
    c = C.contact(plate, _tip(plate), tolerance=0.0)
    cap = np.sqrt(2 * 0.01 * 0.002 - 0.002**2)
    r = np.linalg.norm(plate.vertices[:, :2], axis=1)
    expect = np.flatnonzero(r < cap - 1e-4)  # the icosphere is a little inside r
    assert set(expect) <= set(c.vertices) and r[c.vertices].max() < cap + 1e-4
    assert c.penetration.max() == pytest.approx(0.002, abs=5e-5)
    np.testing.assert_allclose(c.force[c.vertices], 0.3 / len(c.vertices))
    assert c.force.sum() == pytest.approx(0.3) and c.pressure == pytest.approx(0.3 / c.area)
    assert c.open_objects == ()


def test_tolerance_widens_the_contact(plate):
    near = C.contact(plate, _tip(plate, depth=-0.001), tolerance=0.0015)  # 1 mm above
    assert near.penetration.max() == 0 and len(near.vertices) >= 1
    with pytest.raises(ValueError, match="no contact: object 'tip' is 1.0 mm from the skin"):
        C.contact(plate, _tip(plate, depth=-0.001), tolerance=0.0005)


def test_splits(plate):
    eq, ar, dp = (
        C.contact(plate, _tip(plate), tolerance=0.0005, split=s) for s in ("equal", "area", "depth")
    )
    for c in (eq, ar, dp):
        assert c.force.sum() == pytest.approx(0.3)
    v = ar.vertices
    np.testing.assert_allclose(
        ar.force[v] / ar.force[v].sum(), plate.vertex_areas[v] / plate.vertex_areas[v].sum()
    )
    deepest = dp.vertices[np.argmax(dp.penetration[dp.vertices])]
    assert dp.force[deepest] == dp.force.max() > eq.force[deepest]
    w = dp.penetration[v] + 0.0005
    np.testing.assert_allclose(dp.force[v], 0.3 * w / w.sum(), rtol=1e-6)


def test_objects_add_up_and_the_scene_knows_its_source(plate):
    a = _tip(plate, at=(0.03, 0.0, 0.0), total=0.2)
    b = _tip(plate, at=(-0.03, 0.0, 0.0), total=0.1)
    c = C.contact(plate, [a, b])
    assert c.total == pytest.approx(0.3) and c.force.sum() == pytest.approx(0.3)
    assert set(c.touched[0]).isdisjoint(c.touched[1])
    scene = Scene.from_load(plate, np.full(plate.n_vertices, 0.005), c.load())
    assert scene.load.kind == "contact" and scene.load.source is c
    assert [o["name"] for o in scene.load.to_dict()["params"]["objects"]] == ["tip", "tip"]
    np.testing.assert_array_equal(scene.force, c.force)


def test_an_open_mesh_is_used_and_named(plate):
    tip = objects.sphere(0.01)
    cut = tip.copy()
    cut.update_faces(cut.face_normals[:, 2] < 0.9)  # a hole on top
    assert not cut.is_watertight
    pose = objects.press(plate, tip, [0.0, 0.0, 0.0], depth=0.002)
    closed = C.contact(plate, C.Pressing(tip, pose, 0.3, "tip"), tolerance=0.0)
    opened = C.contact(plate, C.Pressing(cut, pose, 0.3, "cut"), tolerance=0.0)
    assert opened.open_objects == ("cut",)
    np.testing.assert_array_equal(opened.vertices, closed.vertices)  # a small hole is harmless


def test_winding_number_of_a_closed_mesh():
    box = trimesh.creation.box([1.0, 1.0, 1.0])
    w = C.winding_number(box, np.array([[0.0, 0, 0], [0.4, 0.4, 0.4], [0.6, 0, 0], [3, 3, 3]]))
    np.testing.assert_allclose(w, [1, 1, 0, 0], atol=1e-9)


def test_the_far_field_winding_number_meets_the_exact_sum():
    """Clusters seen from afar count as dipoles: within 1 % of the exact sum of every
    triangle's solid angle, and the same side of every point, on and off a sphere's skin.
    """
    sphere = trimesh.creation.icosphere(3)  # 1280 triangles, radius 1
    rng = np.random.default_rng(0)
    x = rng.normal(size=(400, 3))
    x /= np.linalg.norm(x, axis=1, keepdims=True)
    points = x * rng.uniform(0.0, 2.0, (400, 1))  # inside, near the skin and outside
    tri = np.asarray(sphere.triangles)
    exact = np.array(
        [C.solid_angles(tri, np.repeat(q[None], len(tri), 0)).sum() for q in points]
    ) / (4 * np.pi)
    fast = C.winding_number(sphere, points)
    assert np.abs(fast - exact).max() < 0.01
    few = C.winding_number(sphere, points[:10])  # a few points: every triangle, exactly
    np.testing.assert_allclose(few, exact[:10], rtol=0, atol=1e-12)
    np.testing.assert_array_equal(fast > 0.5, exact > 0.5)
    inside = np.linalg.norm(points, axis=1) < 0.95  # clear of the facets
    assert (fast[inside] > 0.99).all() and (
        fast[np.linalg.norm(points, axis=1) > 1.05] < 0.01
    ).all()


@pytest.mark.parametrize(
    "make,message",
    [
        (lambda m: C.Pressing(m, np.full((4, 4), np.nan)), "pose is not finite"),
        (lambda m: C.Pressing(m, np.diag([2.0, 1, 1, 1])), "not a rigid transform"),
        (lambda m: C.Pressing(m, np.eye(3)), r"\(4, 4\) matrix"),
        (lambda m: C.Pressing(m, total=-1), "total force must be finite and > 0"),
        (lambda m: C.Pressing(trimesh.Trimesh(np.zeros((3, 3)), [[0, 1, 2]])), "degenerate"),
        (
            lambda m: C.Pressing(trimesh.Trimesh(np.zeros((0, 3)), np.zeros((0, 3), int))),
            "no faces",
        ),
        (lambda m: C.pose_matrix([0, 0, np.inf]), "position must be 3 finite numbers"),
    ],
)
def test_bad_objects_are_named(make, message):
    with pytest.raises(ValueError, match=message):
        make(objects.sphere(0.01))


def test_mesh_files(tmp_path, plate):
    tip = objects.sphere(0.01)
    for ext in (".stl", ".ply", ".obj", ".glb"):
        f = tmp_path / f"tip{ext}"
        tip.export(f)
        back = C.read_mesh(f)
        assert back.volume == pytest.approx(tip.volume, rel=1e-6), ext
    (tmp_path / "junk.obj").write_text("this is not a mesh\n")
    with pytest.raises(ValueError, match="junk.obj (is not a readable mesh|holds no triangle)"):
        C.read_mesh(tmp_path / "junk.obj")
    (tmp_path / "tip.txt").write_text("v 0 0 0\n")
    with pytest.raises(ValueError, match="not a mesh file stmpl reads"):
        C.read_mesh(tmp_path / "tip.txt")
    with pytest.raises(FileNotFoundError, match="mesh file not found"):
        C.read_mesh(tmp_path / "none.stl")
    (tmp_path / "nan.obj").write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 nan\nf 1 2 3\nf 1 2 4\n")
    with pytest.raises(ValueError, match="1 of its 4 vertices are not finite .the first: vertex 3"):
        C.read_mesh(tmp_path / "nan.obj")


def test_pose_matrix_rotation_vector():
    P = C.pose_matrix([1, 2, 3], [0, 0, np.pi / 2])
    np.testing.assert_allclose(P[:3, :3] @ [1, 0, 0], [0, 1, 0], atol=1e-12)
    np.testing.assert_allclose(P[:3, 3], [1, 2, 3])


def test_an_object_that_encloses_the_whole_part_is_named(plate):
    big = objects.sphere(10.0)  # a 1 cm sphere read from millimetres as metres
    big.apply_translation(-big.bounds.mean(0))  # centred on the plate
    with pytest.raises(ValueError, match="encloses the whole of 'sheet'.*a mesh in millimetres"):
        C.contact(plate, [C.Pressing(big, np.eye(4), 0.2, "ball")])


def test_the_distance_to_a_mesh_is_exact_and_bounded_past_what_is_asked():
    """Against brute force over every triangle (:func:`stmpl.geometry.closest_points`): exact
    everywhere by default; with ``upto``, exact where it is at most that, and a lower bound
    above it elsewhere; also on a mesh of fine and long triangles together (a fine ball beside
    a box of 5 cm faces), which are searched in groups by size.
    """
    rng = np.random.default_rng(0)
    box = trimesh.creation.box((0.05, 0.02, 0.01))
    mixed = trimesh.util.concatenate(
        [objects.sphere(0.01), box.copy().apply_translation((0.02, 0, 0))]
    )
    for mesh in (objects.sphere(0.01), box, mixed):
        points = rng.normal(0, 0.02, (300, 3))
        tri = mesh.triangles
        brute = np.array(
            [
                np.linalg.norm(
                    closest_points(tri, np.repeat(p[None], len(tri), 0))[0] - p, axis=1
                ).min()
                for p in points
            ]
        )
        np.testing.assert_allclose(C.distance_to_surface(mesh, points), brute, atol=1e-12)
        near = C.distance_to_surface(mesh, points, upto=0.003)
        close = brute <= 0.003
        np.testing.assert_allclose(near[close], brute[close], atol=1e-12)
        assert np.all(near[~close] > 0.003) and np.all(near[~close] <= brute[~close] + 1e-12)
