"""A scene given by where an object is: the pose's checks, the scene that carries it, its
answer's force and reaction, and both written to a file and read back.
"""

import pickle

import numpy as np
import pytest

from stmpl import tissue
from stmpl.body import tube
from stmpl.pose import GAP_REACH, Pose, Rigid
from stmpl.scene import Deformation, Scene


@pytest.fixture(scope="module")
def part():
    return tube(n_around=16, n_along=11)


def _pose(part, gap=None):
    box = Rigid(
        "box", [[0, 0, 0], [1e-2, 0, 0], [0, 1e-2, 0], [0, 0, 1e-2]], [[0, 2, 1], [0, 1, 3]]
    )
    g = np.full(part.n_vertices, GAP_REACH) if gap is None else gap
    g = g.copy()
    g[3] = -0.002
    return Pose(g, [0.0, 0.0, -1.0], (box,))


def test_a_posed_scene_gives_its_pose_and_asks_for_its_force(part):
    s = Scene.posed(part, tissue.constant(part, 0.0075), _pose(part), id=3)
    assert s.given == "pose" and s.force is None and s.meta == {"id": 3}
    assert s.pose.depth == pytest.approx(0.002) and list(s.pose.touched) == [3]
    assert s.pose.nearest() == (
        "the skin vertex nearest it 2.00 mm inside it along the press at rest"
    )
    assert list(s.pose.near(0.001)) == [3] and len(s.pose.near(0.03)) == part.n_vertices
    with pytest.raises(ValueError, match="gives an object's pose, not a force"):
        s.total_force
    with pytest.raises(ValueError, match="force or an object's pose, not both"):
        Scene(part, s.thickness, np.zeros(part.n_vertices), pose=s.pose)
    with pytest.raises(ValueError, match="a force per vertex or an object's pose"):
        Scene(part, s.thickness)
    with pytest.raises(ValueError, match=r"gap must have shape \(176,\)"):
        Scene.posed(part, s.thickness, Pose(np.zeros(5), [0, 0, 1.0], s.pose.objects))


@pytest.mark.parametrize(
    "change, message",
    [
        (dict(gap=np.array([0.0, np.nan])), "gap is not finite at vertex 1"),
        (dict(gap=np.array([0.0, 0.05])), "cut at 20 mm"),
        (dict(direction=[0.0, 0.0, 2.0]), "unit 3-vector"),
        (dict(objects=("box",)), "must be Rigid objects"),
    ],
)
def test_a_bad_pose_is_named(change, message):
    box = Rigid("box", np.eye(3), [[0, 1, 2]])
    args = {"gap": np.zeros(2), "direction": [0.0, 0.0, 1.0], "objects": (box,), **change}
    with pytest.raises(ValueError, match=message):
        Pose(**args)
    with pytest.raises(ValueError, match="faces index vertices outside 0..2"):
        Rigid("box", np.eye(3), [[0, 1, 3]])
    with pytest.raises(ValueError, match="vertex 1 is not finite"):
        Rigid("box", [[0, 0, 0], [np.inf, 0, 0], [0, 1, 0]], [[0, 1, 2]])


def test_the_answer_to_a_pose_carries_its_force_and_reaction_through_a_file(part, tmp_path):
    s = Scene.posed(part, tissue.constant(part, 0.0075), _pose(part))
    u = np.zeros((part.n_vertices, 3))
    u[3] = [0, 0, -0.0015]
    f = np.zeros(part.n_vertices)
    f[3] = 0.2
    d = Deformation(s, u, {"predictor": "test"}, f, 0.19)
    assert d.pressure[3] == pytest.approx(0.2 / part.vertex_areas[3])
    back = Deformation.read(d.save(tmp_path / "d.npz"))
    assert back.scene.given == "pose" and back.reaction == pytest.approx(0.19)
    np.testing.assert_array_equal(back.force, f)
    np.testing.assert_array_equal(back.scene.pose.gap, s.pose.gap)
    np.testing.assert_array_equal(back.scene.pose.objects[0].faces, s.pose.objects[0].faces)
    assert back.scene.pose.names() == ["box"]
    with pytest.raises(ValueError, match="needs its force and its reaction"):
        Deformation(s, u)
    with pytest.raises(ValueError, match="finite forces >= 0 N"):
        Deformation(s, u, {}, -f, 0.19)
    loaded = Scene(part, s.thickness, f)
    with pytest.raises(ValueError, match="no answered force or reaction"):
        Deformation(loaded, u, {}, f, 0.2)


def test_a_pose_s_way_field_is_checked_and_travels_through_its_arrays(part):
    """The way field (how the objects' surface moves near each vertex) is one finite 3-vector
    per vertex, kept read-only and written with the pose's arrays; without it a pose has none.
    """
    p = _pose(part)
    assert p.way is None and "way" not in p.arrays()
    way = np.zeros((part.n_vertices, 3))
    way[3] = [0.0, 0.6, -0.8]
    q = Pose(p.gap, p.direction, p.objects, way)
    assert not q.way.flags.writeable
    back = Pose.from_arrays(q.arrays(), q.names())
    np.testing.assert_array_equal(back.way, way)
    with pytest.raises(ValueError, match=r"Pose.way must be \(N, 3\)"):
        Pose(p.gap, p.direction, p.objects, way[:-1])
    way[5, 1] = np.nan
    with pytest.raises(ValueError, match="Pose.way is not finite at vertex 5"):
        Pose(p.gap, p.direction, p.objects, way)


def test_a_way_given_as_a_function_is_computed_once_when_first_read(part):
    """A way field given as a function costs nothing until read (a grip's is a search of the
    hand's surface, and only a model with ``motion`` reads it); read, it is checked like a
    given one, kept, and a pickled pose carries it.
    """
    p = _pose(part)
    way = np.zeros((part.n_vertices, 3))
    way[3] = [0.0, 0.6, -0.8]
    calls = []

    def compute():
        calls.append(1)
        return way

    q = Pose(p.gap, p.direction, p.objects, compute)
    assert calls == []
    np.testing.assert_array_equal(q.way, way)
    np.testing.assert_array_equal(q.way, way)
    assert len(calls) == 1 and not q.way.flags.writeable
    back = pickle.loads(pickle.dumps(q))
    np.testing.assert_array_equal(back.way, way)
    np.testing.assert_array_equal(back.gap, p.gap)
    with pytest.raises(AttributeError, match="read-only"):
        q.gap = p.gap
    bad = Pose(p.gap, p.direction, p.objects, lambda: way[:-1])
    with pytest.raises(ValueError, match=r"Pose.way must be \(N, 3\)"):
        bad.way
