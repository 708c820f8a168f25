"""The FEM's rigid objects: exact signed distances, and a triangle mesh's distance against them."""

import numpy as np
import pytest
import trimesh

from fem.shapes import BAND, Box, Punch, Sphere, Surface, skin_near, touching


def test_signed_distances_of_the_shapes():
    x = np.array([[0.0, 0, 2], [0, 0, 0.5], [3, 0, 1], [0.5, 0.5, 0.5]])
    phi, grad, _ = Sphere([0, 0, 1], 1.0).distance(x)
    np.testing.assert_allclose(phi, [0.0, -0.5, 2.0, np.sqrt(0.75) - 1])
    np.testing.assert_allclose(np.linalg.norm(grad, axis=1), 1.0)
    punch = Punch([0, 0, 0], [0, 0, -1], 1.0)  # face at z = 0 pressing down, body above
    phi, grad, _ = punch.distance(np.array([[0, 0, -0.3], [0, 0, 0.2], [2, 0, 0.5], [2, 0, -1]]))
    np.testing.assert_allclose(phi, [0.3, -0.2, 1.0, np.sqrt(2)])
    np.testing.assert_allclose(grad[0], [0, 0, -1])
    np.testing.assert_allclose(grad[2], [1, 0, 0])
    box = Box([0, 0, 0], [1, 2, 3])
    phi, grad, _ = box.distance(np.array([[0, 0, 0], [2, 0, 0], [0.5, 1.9, 0]]))
    np.testing.assert_allclose(phi, [-1, 1, -0.1])
    np.testing.assert_allclose(grad[1:], [[1, 0, 0], [0, 1, 0]])


def test_a_rounded_punch_is_the_sharp_one_with_its_rim_rounded():
    """Over the middle of its face and beside its straight side the rounded punch is the sharp
    one; at the rim it is a torus of the rounding's radius: a point off the corner lies that
    radius less from the rim's circle than from the sharp corner, and its normal points from
    the circle. The rounding must stay below the radius.
    """
    down = np.array([0.0, 0, -1])
    sharp, round_ = Punch([0, 0, 0], down, 1.0), Punch([0, 0, 0], down, 1.0, rounding=0.2)
    flat = np.array([[0.0, 0, -0.3], [0.5, 0, -0.1], [1.5, 0, 0.5], [-1.1, 0, 2.0]])
    np.testing.assert_allclose(round_.distance(flat)[0], sharp.distance(flat)[0], atol=1e-12)
    corner = np.array([[1.3, 0, -0.3]])  # off the rim, diagonally
    phi, grad, _ = round_.distance(corner)
    circle = np.array([0.8, 0, 0.2])  # on the centre line of the rounded rim, behind the face
    assert phi[0] == pytest.approx(np.linalg.norm(corner[0] - circle) - 0.2)
    np.testing.assert_allclose(grad[0], (corner[0] - circle) / np.linalg.norm(corner[0] - circle))
    assert phi[0] > sharp.distance(corner)[0][0]
    with pytest.raises(ValueError, match="rounding must be >= 0 and below the radius"):
        Punch([0, 0, 0], down, 1.0, rounding=1.0)


def _points(rng, n, half):
    return rng.uniform(-half, half, size=(n, 3))


def test_a_box_mesh_has_the_box_exact_distance_within_the_band():
    """A box's mesh (12 triangles) without rounding: the same signed distance and normal as
    the exact box, inside and out, wherever the distance is exact (within BAND).
    """
    half = np.array([0.01, 0.02, 0.015])
    mesh = trimesh.creation.box(extents=2 * half)
    surface = Surface(mesh.vertices, mesh.faces, rounding=0.0)
    x = _points(np.random.default_rng(0), 4000, 0.03)
    phi, grad, _ = surface.distance(x)
    exact, exact_grad, _ = Box([0, 0, 0], half).distance(x)
    band = np.abs(exact) < BAND
    assert band.sum() > 300 and (band & (exact < 0)).sum() > 100
    np.testing.assert_allclose(phi[band], exact[band], atol=1e-12)
    np.testing.assert_allclose(grad[band], exact_grad[band], atol=1e-9)
    far = ~band & ~np.isclose(phi, exact, rtol=0, atol=1e-12)
    assert far.any() and np.all(phi[far] == BAND)  # a lower bound where no pressure reaches


def test_a_sphere_mesh_is_the_sphere_up_to_its_facets_and_rounding():
    """An icosphere of radius 8 mm (2562 vertices), rounded by 0.5 mm: the distance of a
    sphere of 8.5 mm within the facets' sagitta (about 0.01 mm).
    """
    r, rounding = 0.008, 5e-4
    mesh = trimesh.creation.icosphere(subdivisions=4, radius=r)
    surface = Surface(mesh.vertices, mesh.faces, rounding=rounding).moved(np.array([0, 0, r]))
    rng = np.random.default_rng(1)
    x = rng.normal(size=(3000, 3))
    x = x / np.linalg.norm(x, axis=1)[:, None] * rng.uniform(0.5 * r, r + 4e-3, (3000, 1))
    x += [0, 0, r]
    phi, grad, _ = surface.distance(x)
    exact, exact_grad, _ = Sphere([0, 0, r], r + rounding).distance(x)
    plane = np.abs(np.einsum("ij,ij->i", mesh.face_normals, mesh.triangles[:, 0]))
    sagitta = r - plane.min()  # how far a face's centre lies under the sphere
    band = np.abs(exact) < BAND - sagitta
    assert band.sum() > 1000
    assert np.abs(phi - exact)[band].max() <= sagitta + 1e-9
    assert np.einsum("ij,ij->i", grad, exact_grad)[band].min() > 0.99
    # farther: BAND or more, on the right side
    assert np.all(np.abs(phi[~band]) >= BAND - 2 * sagitta)
    assert np.all(np.sign(phi[~band]) == np.sign(exact[~band]))


def test_a_mesh_moves_or_closes_along_its_path():
    mesh = trimesh.creation.box(extents=(0.02, 0.02, 0.02))
    surface = Surface(mesh.vertices, mesh.faces, rounding=0.0)
    down = np.array([0.0, 0, -1])
    moved = surface.pushed(0.003, down)
    np.testing.assert_allclose(moved.vertices, mesh.vertices + [0, 0, -0.003])
    path = np.where(mesh.vertices[:, 2:] > 0, down, 0.0)  # the top face comes down
    squeezed = Surface(mesh.vertices, mesh.faces, rounding=0.0, path=path).pushed(0.004, None)
    phi, _, _ = squeezed.distance(np.array([[0.0, 0, 0.007], [0, 0, 0.005]]))
    np.testing.assert_allclose(phi, [0.001, -0.001], atol=1e-12)
    with pytest.raises(ValueError, match="without a path needs a direction"):
        surface.pushed(0.001, None)
    with pytest.raises(ValueError, match="closes along it, not a direction"):
        Surface(mesh.vertices, mesh.faces, path=path).pushed(0.001, down)


@pytest.mark.parametrize(
    "make, message",
    [
        (lambda: Sphere([0, 0, np.nan], 1.0), "centre must be a finite 3-vector"),
        (lambda: Sphere([0, 0, 0], 0.0), "radius must be > 0"),
        (lambda: Punch([0, 0, 0], [0, 0, 0], 1.0), "nonzero 3-vector"),
        (lambda: Box([0, 0, 0], [1, -1, 1]), "three positive lengths"),
        (lambda: Surface([[0, 0, 0], [1, 0, 0], [0, np.inf, 0]], [[0, 1, 2]]), "finite"),
        (lambda: Surface([[0, 0, 0], [1, 0, 0], [0, 1, 0]], [[0, 1, 3]]), "outside 0..2"),
        (lambda: Surface([[0, 0, 0], [1, 0, 0], [2, 0, 0]], [[0, 1, 2]]), "degenerate"),
        (lambda: Surface([[0, 0, 0], [1, 0, 0], [0, 1, 0]], [[0, 1, 2]], rounding=-1), "rounding"),
        (
            lambda: Surface([[0, 0, 0], [1, 0, 0], [0, 1, 0]], [[0, 1, 2]], path=np.zeros((2, 3))),
            "path must be",
        ),
    ],
)
def test_bad_shapes_are_named(make, message):
    with pytest.raises(ValueError, match=message):
        make()


def test_a_punch_in_a_hollow_is_set_back_to_first_contact():
    """A flat punch set on the bottom of a hollow (a bowl of radius 50 mm) starts with the
    hollow's sides inside it; moved back to first contact, its face stands the bowl's rise at
    its rim (r^2 / 2R = 1 mm for r = 10 mm) above the bottom and just touches. A ball over a
    flat plane is left where it is.
    """
    g = np.linspace(-0.03, 0.03, 61)
    x, y = np.meshgrid(g, g)
    R = 0.05
    bowl = np.column_stack(
        [x.ravel(), y.ravel(), R - np.sqrt(R**2 - x.ravel() ** 2 - y.ravel() ** 2)]
    )
    down = np.array([0.0, 0.0, -1.0])
    punch = Punch(np.zeros(3), down, 0.01)
    assert punch.distance(bowl)[0].min() < -5e-4  # the rim is inside it
    set_back = touching(punch, down, bowl)
    rise = R - np.sqrt(R**2 - 0.01**2)  # 1.0 mm at the punch's rim
    assert set_back.centre[2] == pytest.approx(rise, abs=2e-6)
    assert -1e-6 <= set_back.distance(bowl)[0].min() <= 2e-6
    plane = np.column_stack([x.ravel(), y.ravel(), np.zeros(x.size)])
    ball = Sphere(np.array([0.0, 0.0, 0.008]), 0.008)
    assert touching(ball, down, plane) is ball


def test_the_skin_near_a_point_samples_its_faces():
    """The points lie on the part's faces within the radius, the vertices among them, and
    faces are sampled between their vertices (a flat punch on a hollow meets those first).
    """
    from stmpl.body.primitives import tube

    part = tube(0.04, 0.3, 24, 30)
    p = part.vertices[100]
    x = skin_near(part, p, 0.02)
    assert np.linalg.norm(x - p, axis=1).max() < 0.02
    near = part.vertices[np.linalg.norm(part.vertices - p, axis=1) < 0.02]
    assert all(np.isclose(x, v).all(1).any() for v in near)
    radius = np.linalg.norm(x[:, :2], axis=1)  # chords of the tube lie inside its radius
    assert radius.min() < 0.04 * np.cos(np.pi / 24) + 1e-6 and radius.max() <= 0.04 + 1e-9


def test_a_large_mesh_s_distance_is_exact_within_the_band_and_bounded_beyond():
    """On a mesh of 20,480 faces (a hand has 50,864), most of the skin lies far outside: those
    points are searched only as far as the band needs. Within the band the distance is the
    exact one (:meth:`Surface.closest` unbounded); beyond, outside points get BAND or more
    (BAND itself, or their distance to a triangle nearby: never less), inside ones -BAND or
    their exact distance.
    """
    r = 0.01
    mesh = trimesh.creation.icosphere(subdivisions=5, radius=r)
    surface = Surface(mesh.vertices, mesh.faces, rounding=5e-4)
    rng = np.random.default_rng(2)
    x = rng.normal(size=(4000, 3))
    x = x / np.linalg.norm(x, axis=1)[:, None] * rng.uniform(0.3 * r, 3 * r, (4000, 1))
    phi, _, _ = surface.distance(x)
    _, dist, c, _ = surface.closest(x)
    outside = np.einsum("ij,ij->i", x - c, c) > 0  # the sphere's normal at c is c itself
    true = np.where(outside, dist, -dist) - surface.rounding
    band = np.abs(true) < BAND
    assert band.sum() > 200 and (~band & outside).sum() > 1000 and (~band & ~outside).sum() > 100
    np.testing.assert_array_equal(phi[band], true[band])
    beyond = ~band & outside
    assert np.all(phi[beyond] >= BAND)
    bounded = phi[beyond] > BAND
    assert bounded.any() and np.all(phi[beyond][bounded] >= true[beyond][bounded] - 1e-15)
    deep = ~band & ~outside
    known = phi[deep] != -BAND  # the exact distance, where the search found it
    assert np.all(phi[deep] <= -BAND) and (~known).any()
    np.testing.assert_array_equal(phi[deep][known], true[deep][known])
