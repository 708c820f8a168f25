"""Scenes given by where objects are: the gap field against a sphere's closed form, the
direction a posed object presses along, and several objects at once.
"""

import numpy as np
import pytest
import trimesh

from stmpl import tissue
from stmpl.body import tube
from stmpl.contact import gap, objects
from stmpl.contact.posing import moved, posed, signed_distance
from stmpl.pose import GAP_REACH, Pose, Rigid
from stmpl.scene import Scene


@pytest.fixture(scope="module")
def part():
    return tube(radius=0.04, length=0.12, n_around=32, n_along=16)


def test_the_signed_distance_is_a_spheres_own_within_its_facets():
    ball = objects.sphere(0.01, subdivisions=4)  # centred at (0, 0, 0.01)
    x = np.random.default_rng(0).uniform(-0.02, 0.04, size=(400, 3))
    exact = np.linalg.norm(x - [0, 0, 0.01], axis=1) - 0.01
    got = signed_distance(ball, x, upto=GAP_REACH)
    near = exact < GAP_REACH - 1e-4
    np.testing.assert_allclose(got[near], exact[near], atol=5e-5)  # facets of 10 mm / 100
    assert (got[~near] >= GAP_REACH - 1e-4).all() and got.max() <= GAP_REACH
    assert (got[exact < -1e-4] < 0).all() and (got[exact > 1e-4] > 0).all()


def test_a_posed_fingertip_gives_the_gap_field_and_its_direction(part):
    tip = objects.sphere(0.008)
    pose = objects.press(part, tip, uv=(0.5, 0.5), depth=0.003)
    s = posed(part, tissue.constant(part, 0.0075), tip, pose, name="fingertip")
    assert s.given == "pose" and s.pose.names() == ["fingertip"]
    np.testing.assert_allclose(s.pose.direction, pose[:3, :3] @ [0, 0, -1], atol=1e-12)
    centre = (pose @ [0, 0, 0.008, 1.0])[:3]
    signed = np.linalg.norm(part.vertices - centre, axis=1) - 0.008
    exact = np.minimum(gap.ball(part.vertices, centre, 0.008, s.pose.direction), signed)
    near = exact < 0.01
    assert (exact < signed - 1e-4).sum() >= 1  # inside: the deeper gap along the press
    np.testing.assert_allclose(s.pose.gap[near], exact[near], atol=2e-4)  # 8 mm icosphere
    assert 0 < s.pose.depth <= 0.003 + 2e-4 and len(s.pose.touched) >= 1
    np.testing.assert_allclose(
        s.pose.objects[0].vertices, tip.copy().apply_transform(pose).vertices
    )


def test_two_objects_give_the_nearer_distance_and_one_direction(part):
    tip = objects.sphere(0.008)
    a = objects.press(part, tip, uv=(0.3, 0.5), depth=0.002)
    b = objects.press(part, tip, uv=(0.7, 0.5), depth=0.002)
    one = posed(part, tissue.constant(part, 0.0075), tip, a)
    two = posed(part, tissue.constant(part, 0.0075), [(tip, a, "index"), (tip, b, "thumb")])
    assert two.pose.names() == ["index", "thumb"]
    assert (two.pose.gap <= one.pose.gap + 1e-12).all()
    assert (two.pose.gap < one.pose.gap - 1e-3).any()  # the thumb's side
    with pytest.raises(ValueError, match="finite nonzero 3-vector"):
        posed(part, tissue.constant(part, 0.0075), tip, a, direction=[0, 0, 0])
    with pytest.raises(ValueError, match="at least one object"):
        posed(part, tissue.constant(part, 0.0075), [])
    with pytest.raises(TypeError, match="'ball': the mesh must be a trimesh.Trimesh"):
        posed(part, tissue.constant(part, 0.0075), "ball.stl", a, name="ball")
    with pytest.raises(ValueError, match="not a rigid transform"):
        posed(part, tissue.constant(part, 0.0075), tip, 2 * a)


def test_a_moved_pose_is_the_pose_pressed_that_much_deeper(part):
    """Moving a posed fingertip 1.5 mm further along its press gives the gap field of the
    fingertip placed 1.5 mm deeper; moving it back, of the one placed shallower; a closing
    object moves along its own path.
    """
    tip = objects.sphere(0.008)
    t = tissue.constant(part, 0.0075)
    at = posed(part, t, tip, objects.press(part, tip, uv=(0.5, 0.5), depth=0.001))
    deeper = posed(part, t, tip, objects.press(part, tip, uv=(0.5, 0.5), depth=0.0025))
    np.testing.assert_allclose(moved(at, 0.0015).pose.gap, deeper.pose.gap, atol=1e-9)
    np.testing.assert_allclose(moved(deeper, -0.0015).pose.gap, at.pose.gap, atol=1e-9)
    assert moved(at, 0.0015).pose.depth == pytest.approx(deeper.pose.depth, abs=1e-12)
    assert deeper.pose.depth > 0.001
    o = at.pose.objects[0]
    path = np.tile(at.pose.direction, (len(o.vertices), 1))  # closing straight along the press
    closing = Scene.posed(
        at.part, t, Pose(at.pose.gap, None, (Rigid(o.name, o.vertices, o.faces, path),))
    )
    np.testing.assert_allclose(
        moved(closing, 0.0015).pose.objects[0].vertices, deeper.pose.objects[0].vertices, atol=1e-12
    )
    d = deeper.pose.objects[0]
    near = signed_distance(trimesh.Trimesh(d.vertices, d.faces), part.vertices)  # its gap
    np.testing.assert_allclose(moved(closing, 0.0015).pose.gap, near, atol=1e-12)
    with pytest.raises(ValueError, match="must be finite"):
        moved(at, float("nan"))
    with pytest.raises(ValueError, match="only a scene given by objects at their pose"):
        moved(Scene(part, t, np.zeros(part.n_vertices)), 0.001)


def test_a_dataset_s_object_at_first_touch_moved_by_its_depth_is_its_sample_s_pose(tiny_presses):
    """A pressed disk's and ball's recorded pose moved back by its depth and meshed
    (:func:`first_touch`), then pressed that depth again, gives the gap field the samples
    record (the closed forms along the press) within the meshes' facets.
    """
    from stmpl.contact.posing import first_touch
    from stmpl.data.dataset import Dataset
    from stmpl.pipeline.evaluate import scenes_of

    ds = Dataset(tiny_presses)
    kinds = set()
    for split in ("train", "val", "test"):
        a = ds.arrays(split)
        scenes, _ = scenes_of(ds, split, given="pose")
        for s, kind, params in zip(scenes, a["kind"], a["params"]):
            start = first_touch(s.part, s.thickness, kind, params)
            again = moved(start, float(params["depth"]))
            near = s.pose.gap < 0.005
            np.testing.assert_allclose(again.pose.gap[near], s.pose.gap[near], atol=1e-4)
            kinds.add(kind)
    assert kinds == {"press_disk", "press_sphere"}
    with pytest.raises(ValueError, match="does not record its object's pose"):
        first_touch(s.part, s.thickness, "press_sphere", {"radius": 0.008})


def test_posed_moved_and_a_dataset_s_grip_carry_the_way_the_objects_move(part, monkeypatch):
    """A posed fingertip's way is its press direction near it; a closing object moved along
    its path carries that path; a grip sample's way is its hand closed the recorded depth
    (the grip read from :func:`cached_closing_grip`), the paths of the hand vertices nearest
    each skin vertex.
    """
    from stmpl.contact import posing

    tip = objects.sphere(0.008)
    t = tissue.constant(part, 0.0075)
    at = posed(part, t, tip, objects.press(part, tip, uv=(0.5, 0.5), depth=0.001))
    near = at.pose.gap < GAP_REACH
    np.testing.assert_allclose(at.pose.way[near], np.tile(at.pose.direction, (near.sum(), 1)))
    assert not at.pose.way[~near].any() and (~near).any()
    o = at.pose.objects[0]
    path = np.tile([0.0, 0.6, 0.0], (len(o.vertices), 1)) + 0.8 * at.pose.direction
    hand = Rigid("hand", o.vertices, o.faces, path)
    closing = moved(Scene.posed(part, t, Pose(at.pose.gap, None, (hand,))), 0.0005)
    near = closing.pose.gap < GAP_REACH
    np.testing.assert_allclose(closing.pose.way[near], np.tile(path[0], (near.sum(), 1)))
    monkeypatch.setattr(posing, "cached_closing_grip", lambda *a, **k: hand)
    params = {"along": 0.5, "around": 0.0, "grip": "pinch", "depth": 0.0005}
    w = posing.sample_way(part, "press_grip", params, closing.pose.gap)
    np.testing.assert_allclose(w, closing.pose.way)
    with pytest.raises(ValueError, match="does not record its placement and depth"):
        posing.sample_way(part, "press_grip", {"grip": "pinch"}, closing.pose.gap)


def test_a_closing_object_moved_is_measured_again_only_where_its_side_may_change(part, monkeypatch):
    """A closing object moved along its path: the gap field measured from the one before (the
    winding numbers only within the move of the surface) is the one measured afresh, skin
    sinking inside and the object drawn back alike; and fewer winding numbers are measured.
    """
    from stmpl.contact import posing

    tip = objects.sphere(0.008)
    t = tissue.constant(part, 0.0075)
    at = posed(part, t, tip, objects.press(part, tip, uv=(0.5, 0.5), depth=0.001))
    o = at.pose.objects[0]
    rng = np.random.default_rng(3)  # each vertex its own way: the surface sweeps, not slides
    path = 0.8 * at.pose.direction + rng.uniform(-0.3, 0.3, (len(o.vertices), 3))
    gap0 = signed_distance(trimesh.Trimesh(o.vertices, o.faces, process=False), part.vertices)
    hand = Rigid("hand", o.vertices, o.faces, path)
    scene = Scene.posed(part, t, Pose(gap0, None, (hand,)))  # a closing pose: its signed distance
    counted = []
    measure = posing.winding_number
    monkeypatch.setattr(
        posing, "winding_number", lambda m, x: counted.append(len(x)) or measure(m, x)
    )
    for distance in (0.003, -0.002, 0.006):
        got = moved(scene, distance).pose.gap
        mesh = trimesh.Trimesh(o.vertices + distance * path, o.faces, process=False)
        fresh = signed_distance(mesh, part.vertices)
        np.testing.assert_array_equal(got, fresh)
        assert ((got < 0) != (gap0 < 0)).any() == (distance > 0)  # deeper: skin now inside
        assert counted[-2] < counted[-1] / 2  # the move's winding numbers, then the fresh ones
