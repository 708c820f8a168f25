"""The FEM as a predictor: it reproduces its own dataset and raises (never answers) on a failed
solve.
"""

import numpy as np
import pytest

from fem.material import NeoHookean
from fem.simulate import simulate
from stmpl import loads, predictor, tissue
from stmpl.body.primitives import tube
from stmpl.pipeline.evaluate import scenes_of
from stmpl.pose import GAP_REACH
from stmpl.scene import Scene


def test_fem_predictor_reproduces_the_dataset(ds):
    scenes, truth = scenes_of(ds, "train", limit=4)
    p = predictor.create("fem", res=dict(ds.card["config"]["resolution"]))
    levels = ds.card["config"]["forces"]
    for s, u in zip(scenes, truth):
        k = levels.index(s.meta["total"]) + 1
        p.levels = k  # the dataset reached this level by k continuation steps
        d = p.predict(s)
        np.testing.assert_allclose(d.displacement, u, atol=1e-7)
        assert d.info["ok"] and d.info["iterations"] >= 1


def test_fem_predictor_raises_on_failure(ds):
    s = Scene(
        ds.part,
        np.full(ds.part.n_vertices, 0.005),
        np.where(np.arange(ds.part.n_vertices) == 40, 15.0, 0.0),
    )
    from fem.predictor import FEMFailed

    with pytest.raises(FEMFailed, match="FEM solve failed"):
        predictor.create(
            "fem", res={"subdivisions": 0, "layers": 1, "order": 1}, options=None
        ).predict(s)


def test_a_scene_the_fem_cannot_mesh_is_a_failure_that_says_why(arm):
    """12.5 mm of tissue folds the arm's inner surface where it curves tightest: the FEM
    predictor fails (PredictionFailed, not a bare ValueError) and names the fold.
    """
    from fem.predictor import FEMFailed
    from stmpl import loads, predictor, tissue
    from stmpl.scene import Scene

    scene = Scene.from_load(
        arm, tissue.constant(arm, 0.0125), loads.disk(arm, uv=(0.5, 0.5), radius=0.02, total=0.1)
    )
    with pytest.raises(FEMFailed, match="cannot build the tissue.*folds the inner surface"):
        predictor.create("fem", res="coarse").predict(scene)


def test_the_fem_predictor_solves_a_layered_preset():
    """The paper's load on the forearm preset: the skin spreads the load and the fat
    stiffens, so the dent is shallower than in the gel (0.58 x here); the answer names its
    tissue, and a preset given with a material of its own, or an unknown preset, is refused by
    name.
    """
    part = tube(radius=0.035, length=0.08, n_around=24, n_along=8)
    load = loads.disk(part, uv=(0.5, 0.5), radius=0.012, total=0.3)
    scene = Scene.from_load(part, tissue.constant(part, 0.0075), load)
    deepest = {}
    for name in ("paper", "forearm"):
        fem = predictor.create("fem", res="medium", levels=2, tissue=name)
        d = fem.predict(scene)
        assert d.info["tissue"] == name
        deepest[name] = d.magnitude.max()
    assert deepest["forearm"] < 0.7 * deepest["paper"]
    with pytest.raises(ValueError, match="unknown tissue preset 'gel'"):
        predictor.create("fem", tissue="gel")
    with pytest.raises(ValueError, match="brings its own laws"):
        simulate(part, scene.thickness, scene.force, material=NeoHookean(), tissue="forearm")


def test_the_fem_answers_a_pose_with_its_force_and_reaction_and_others_refuse_it():
    """A fingertip mesh set 2 mm into a tube: the FEM presses it from first contact to the pose
    and answers the dent, the contact force on each vertex and the reaction, as the exact sphere
    pressed as deep does (within the icosphere's facets); a pose short of the skin is no
    contact; a force-in predictor refuses the scene by name.
    """
    from fem.contact import press
    from fem.objects import at_pose
    from fem.shapes import Sphere, clearance, skin_near
    from fem.simulate import tissue_mesh
    from fem.solver import Solver
    from stmpl.contact import objects
    from stmpl.contact.posing import posed

    part = tube(radius=0.04, length=0.12, n_around=24, n_along=10)
    th = tissue.constant(part, 0.0075)
    res = {"subdivisions": 1, "layers": 2, "refine_radius": 0.03, "order": 1}
    tip = objects.sphere(0.008)
    pose = objects.press(part, tip, uv=(0.5, 0.5), depth=0.002)
    scene = posed(part, th, tip, pose, name="fingertip")
    d = predictor.create("fem", res=res).predict(scene)
    assert d.info["depth"] == pytest.approx(0.002, abs=5e-5)
    centre = (pose @ [0, 0, 0.008, 1.0])[:3]
    ball = Sphere(centre, 0.008)
    back = clearance(ball, scene.pose.direction, skin_near(part, centre, 0.03))
    near = part.vertices[scene.pose.near()]
    mesh, _ = tissue_mesh(part, th, res, "paper", None, near)
    (exact,) = press(
        Solver(mesh, NeoHookean(), order=1),
        ball.moved(-back * scene.pose.direction),
        scene.pose.direction,
        [back],
    )
    assert d.reaction == pytest.approx(exact.reaction, rel=0.03)
    peak = np.linalg.norm(exact.displacement, axis=1).max()
    error = np.linalg.norm(d.displacement - exact.displacement, axis=1)
    assert error.mean() <= 0.01 * peak and error.max() <= 0.15 * peak, (error.max(), peak)
    assert d.force.sum() == pytest.approx(d.reaction, rel=0.05) and d.force.min() >= 0
    np.testing.assert_allclose(d.pressure, d.force / part.vertex_areas)
    assert at_pose(part, scene.pose)[1] == pytest.approx(d.info["depth"])
    short = posed(part, th, tip, objects.press(part, tip, uv=(0.5, 0.5), depth=-0.003))
    none = predictor.create("fem", res=res).predict(short)
    assert none.reaction == 0.0 and not none.displacement.any() and not none.force.any()
    with pytest.raises(ValueError, match="naive answers a force given on the skin, and scene 0"):
        predictor.create("naive", part).predict(scene)


@pytest.mark.parametrize("start", [0.001, -0.003])
def test_the_fem_presses_a_pose_to_a_force_with_its_own_force_control(start):
    """Asked for the force a fingertip 2 mm into a tube carries, from a pose 1 mm in or 3 mm
    off the skin, the FEM (handed the request by :func:`stmpl.contact.force_control.to_force`)
    meets it within the tolerance at the fingertip's 2 mm pose: the answer's scene is the
    fingertip there, its dent the 2 mm press's.
    """
    from stmpl.contact import objects
    from stmpl.contact.force_control import to_force
    from stmpl.contact.posing import posed

    part = tube(radius=0.04, length=0.12, n_around=24, n_along=10)
    th = tissue.constant(part, 0.0075)
    res = {"subdivisions": 1, "layers": 2, "refine_radius": 0.03, "order": 1}
    tip = objects.sphere(0.008)
    fem = predictor.create("fem", res=res)
    at = posed(part, th, tip, objects.press(part, tip, uv=(0.5, 0.5), depth=0.002))
    two = fem.predict(at)
    begin = posed(part, th, tip, objects.press(part, tip, uv=(0.5, 0.5), depth=start))
    a = to_force(fem, begin, two.reaction, rtol=0.002)
    assert a.reaction == pytest.approx(two.reaction, rel=0.002)
    fc = a.info["force_control"]
    assert fc["moved_mm"] == pytest.approx(2.0 - 1e3 * start, abs=0.02)
    assert a.scene.pose.depth == pytest.approx(at.pose.depth, abs=2e-5)
    assert a.info["depth"] == pytest.approx(two.info["depth"], abs=2e-5)
    peak = np.linalg.norm(two.displacement, axis=1).max()
    assert np.abs(a.displacement - two.displacement).max() <= 0.01 * peak


def test_a_pose_on_a_subdivided_part_is_solved_on_the_part_it_came_from():
    """The FEM meshes the coarser part (refined once more near the ball) and answers on the
    finer one: a displacement and a contact force on each of its vertices.
    """
    from stmpl.contact import objects
    from stmpl.contact.posing import posed

    coarse = tube(radius=0.04, length=0.1, n_around=16, n_along=8)
    part = coarse.subdivided(1)
    th = tissue.constant(part, 0.0075)
    tip = objects.sphere(0.008)
    scene = posed(part, th, tip, objects.press(part, tip, uv=(0.5, 0.5), depth=0.002))
    res = {"subdivisions": 0, "layers": 2, "refine_radius": 0.03, "order": 2}
    d = predictor.create("fem", res=res).predict(scene)
    assert d.info["mesh"]["skin_vertices"] == coarse.n_vertices
    assert d.displacement.shape == (part.n_vertices, 3)
    assert np.abs(d.displacement).max() == pytest.approx(0.002, rel=0.05)
    # the normal forces on the ball's curve sum to a little more than its push along the press
    assert d.reaction < d.force.sum() < 1.1 * d.reaction and d.force.min() >= 0
    np.testing.assert_allclose(d.pressure, d.force / part.vertex_areas)


def test_a_layered_tissue_in_linear_elements_is_refused():
    """Linear tetrahedra lock in the layered presets' nearly incompressible layers (a fingertip
    3 mm into the forearm carried 6.2 N in them against 0.41 N in quadratic ones): refused when
    the predictor is made, naming the fix.
    """
    with pytest.raises(ValueError, match="lock in linear .* use a resolution of order 2"):
        predictor.create("fem", res="coarse", tissue="forearm")
    assert predictor.create("fem", res="coarse", tissue="paper").tissue == "paper"


def test_the_fem_closes_a_grip_given_by_its_pose(tmp_path):
    """The pinch of anny's hand on a tube given by its pose 2 mm closed
    (``stmpl.contact.posing.gripped``): the FEM finds the depth along the grip's path and
    answers as the grip pressed closed as far from its first touch does, its reaction the
    squeeze; a scene file keeps the pose.
    """
    from fem.contact import press
    from fem.objects import at_pose
    from fem.shapes import ROUNDING, Surface
    from fem.simulate import tissue_mesh
    from fem.solver import Solver
    from stmpl.contact.closing import closed
    from stmpl.contact.hand import Hand
    from stmpl.contact.posing import gripped

    part = tube(radius=0.035, length=0.22, n_around=24, n_along=22)
    th = tissue.constant(part, 0.0075)
    res = {"subdivisions": 0, "layers": 2, "refine_radius": 0.02, "order": 1}
    scene = gripped(part, th, 0.002, Hand(side="R"), along=0.5, kind="pinch")
    assert scene.pose.closing and scene.pose.objects[0].path is not None
    reach = scene.pose.gap < GAP_REACH  # the way the closing fingers move there, none beyond
    assert np.linalg.norm(scene.pose.way[reach], axis=1).max() > 0.5
    assert not scene.pose.way[~reach].any()
    shape, depth = at_pose(part, scene.pose)
    assert depth == pytest.approx(0.002, abs=3e-4)
    d = predictor.create("fem", res=res).predict(scene)
    hand = closed(scene.pose.objects[0], -0.002)  # at first touch, as fem.objects.closing sets it
    closing = Surface(hand.vertices, hand.faces, ROUNDING, hand.path)
    near = part.vertices[scene.pose.gap < 0.005]
    mesh, _ = tissue_mesh(part, th, res, "paper", None, near)
    # the pose's faces, where the FEM's rounded surface presses them to: closed 2 mm less the
    # rounding from where the unrounded hand first touches
    (direct,) = press(Solver(mesh, NeoHookean(), order=1), closing, None, [0.002 - ROUNDING])
    assert direct.ok and d.reaction == pytest.approx(direct.reaction, rel=0.02)
    assert d.reaction == pytest.approx(d.force.sum(), rel=1e-6)  # a grip's reaction: squeeze
    scene.save(tmp_path / "grip.npz")
    back = Scene.read(tmp_path / "grip.npz")
    assert back.pose.closing and np.array_equal(
        back.pose.objects[0].path, scene.pose.objects[0].path
    )
