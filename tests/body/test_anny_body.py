import numpy as np
import pytest
import scipy.sparse as sp
from scipy.sparse import csgraph

from stmpl.body import AnnyBody, BodyModel


def test_left_arm_is_the_papers_part(arm):
    # the reference arm: dominant bones upperarm01/02.L, lowerarm01/02.L, one UV chart
    assert (arm.n_vertices, arm.n_faces) == (541, 1027)
    assert len(arm.seam_vertices) == 24
    assert len(arm.rims) == 2  # shoulder and wrist
    e = np.concatenate([arm.face_uv[:, [0, 1]], arm.face_uv[:, [1, 2]]])
    adj = sp.coo_matrix((np.ones(len(e)), (e[:, 0], e[:, 1])), shape=(len(arm.uv),) * 2)
    assert csgraph.connected_components(adj, directed=False)[0] == 1
    assert arm.uv.min() >= 0.04 - 1e-12 and arm.uv.max() <= 0.96 + 1e-12


def test_arm_normals_point_out_of_the_limb(arm):
    from stmpl.geometry import project_on_polyline

    s = project_on_polyline(arm.vertices, arm.axis)
    seg = np.cumsum(np.r_[0, np.linalg.norm(np.diff(arm.axis, axis=0), axis=1)])
    centre = np.stack([np.interp(s, seg, arm.axis[:, k]) for k in range(3)], 1)
    radial = arm.vertices - centre
    outward = (radial * arm.normals).sum(1) > 0
    assert outward.mean() > 0.95
    # arm radius is human: 2..7 cm
    r = np.linalg.norm(radial, axis=1)
    assert 0.02 < np.median(r) < 0.07


def test_weight_phenotype_thickens_the_arm(tmp_path):
    thin = AnnyBody({"weight": 0.0}, cache_dir=tmp_path).part("left_arm")
    heavy = AnnyBody({"weight": 1.0}, cache_dir=tmp_path).part("left_arm")
    assert heavy.face_areas.sum() > 1.08 * thin.face_areas.sum()


def test_parts_are_cached_and_a_corrupt_cache_is_rebuilt(tmp_path, anny_body):
    body = AnnyBody(cache_dir=tmp_path)
    body._anny = anny_body.anny  # share the loaded model
    a = body.part("left_arm")
    (cached,) = (tmp_path / "parts").glob("anny-left_arm-*.npz")
    b = AnnyBody(cache_dir=tmp_path).part("left_arm")  # from the cache, anny untouched
    np.testing.assert_array_equal(a.vertices, b.vertices)
    cached.write_bytes(b"garbage")
    body2 = AnnyBody(cache_dir=tmp_path)
    body2._anny = anny_body.anny
    np.testing.assert_array_equal(body2.part("left_arm").faces, a.faces)


def test_other_parts(anny_body):
    right = anny_body.part("right_arm")
    assert right.n_vertices == 541
    assert np.allclose(
        right.vertices[:, 0].mean(), -anny_body.part("left_arm").vertices[:, 0].mean()
    )
    belly = anny_body.part("belly")
    assert belly.axis is None and len(belly.rims) == 1 and belly.n_vertices > 200
    mean_normal = belly.normals.sum(0) / np.linalg.norm(belly.normals.sum(0))
    assert mean_normal @ np.array([0, -1.0, 0]) > 0.8  # anny faces -y: the belly looks forward


def test_every_shape_cuts_the_same_belly(tmp_path, anny_body):
    """A front-only part is cut on the template shape: a heavy, muscular body's belly is the
    same mesh (vertices, faces, chart) as the default's, in its own shape.
    """
    heavy = AnnyBody({"weight": 0.98, "muscle": 0.3, "proportions": 0.95}, cache_dir=tmp_path)
    heavy._anny = anny_body.anny
    a, b = anny_body.part("belly"), heavy.part("belly")
    np.testing.assert_array_equal(a.body_index, b.body_index)
    np.testing.assert_array_equal(a.faces, b.faces)
    np.testing.assert_allclose(a.uv, b.uv)
    assert np.abs(a.vertices - b.vertices).max() > 0.01  # another shape


def test_bad_input(anny_body):
    assert isinstance(anny_body, BodyModel)
    with pytest.raises(ValueError, match="unknown part 'leg'"):
        anny_body.part("leg")
    with pytest.raises(ValueError, match="weight must be in"):
        AnnyBody({"weight": 1.5})
    with pytest.raises(ValueError, match="unknown anny phenotype 'mass'"):
        AnnyBody({"mass": 0.5})
