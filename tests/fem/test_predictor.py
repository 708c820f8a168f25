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
