import numpy as np
import pytest

from stmpl import loads, tissue
from stmpl.body import tube
from stmpl.scene import Deformation, Scene


@pytest.fixture(scope="module")
def part():
    return tube(n_around=16, n_along=11)


@pytest.fixture
def scene(part):
    return Scene.from_load(
        part, tissue.constant(part, 0.0075), loads.band(part, 0.5, 0.05, 2.0), id=7
    )


def test_scene_is_frozen_and_read_only(scene):
    with pytest.raises(AttributeError):
        scene.force = None
    with pytest.raises(ValueError):
        scene.force[0] = 1.0
    assert scene.total_force == pytest.approx(2.0)
    np.testing.assert_allclose(np.linalg.norm(scene.force_vectors, axis=1), scene.force)
    assert (np.einsum("ij,ij->i", scene.force_vectors, scene.part.normals) <= 0).all()


def test_scene_and_deformation_save_load_round_trip(scene, tmp_path):
    back = Scene.read(scene.save(tmp_path / "s.npz"))
    assert back.load is None  # a scene read back (or made from arrays) has no Load
    assert Scene(back.part, back.thickness, back.force).load is None
    np.testing.assert_array_equal(back.force, scene.force)
    np.testing.assert_array_equal(back.thickness, scene.thickness)
    np.testing.assert_array_equal(back.part.faces, scene.part.faces)
    assert back.meta == {"id": 7}
    u = np.zeros((scene.part.n_vertices, 3))
    u[:, 2] = -0.001
    d = Deformation(scene, u, {"predictor": "test"})
    d2 = Deformation.read(d.save(tmp_path / "d.npz"))
    np.testing.assert_array_equal(d2.displacement, u)
    assert d2.info == {"predictor": "test"}
    np.testing.assert_allclose(d.mesh().vertices, scene.part.vertices + u)
    np.testing.assert_allclose(d.magnitude, 0.001)
    with pytest.raises(ValueError, match="not a deformation"):
        Deformation.read(tmp_path / "s.npz")


@pytest.mark.parametrize(
    "field,value,message",
    [
        ("force", lambda n: np.full(n, -0.1), "force must be >= 0"),
        ("force", lambda n: np.full(n, np.inf), "not finite at vertex 0"),
        ("force", lambda n: np.zeros(n + 1), "force must have shape"),
        ("force", lambda n: np.full(n, 25.0), "<= 20 N per vertex"),
        ("thickness", lambda n: np.zeros(n), "thickness must lie in"),
        ("thickness", lambda n: np.full(n, 0.013), "thickness must lie in"),
        ("thickness", lambda n: np.full((n, 2), 0.005), "thickness must have shape"),
    ],
)
def test_bad_scenes_are_named(part, field, value, message):
    kw = {"thickness": np.full(part.n_vertices, 0.005), "force": np.zeros(part.n_vertices)}
    kw[field] = value(part.n_vertices)
    with pytest.raises(ValueError, match=message):
        Scene(part, **kw)


def test_bad_deformations_and_files(scene, tmp_path):
    with pytest.raises(ValueError, match="displacement must have shape"):
        Deformation(scene, np.zeros((3, 3)))
    with pytest.raises(ValueError, match="non-finite"):
        Deformation(scene, np.full((scene.part.n_vertices, 3), np.nan))
    with pytest.raises(FileNotFoundError):
        Scene.read(tmp_path / "missing.npz")
    (tmp_path / "junk.npz").write_bytes(b"not a zip")
    with pytest.raises(ValueError, match="not a readable stmpl scene"):
        Scene.read(tmp_path / "junk.npz")
    good = scene.save(tmp_path / "s.npz").read_bytes()
    (tmp_path / "cut.npz").write_bytes(good[: len(good) // 2])
    with pytest.raises(ValueError, match="not a readable"):
        Scene.read(tmp_path / "cut.npz")
