"""The FEM as a predictor: it reproduces its own dataset and raises (never answers) on a failed
solve.
"""

import numpy as np
import pytest

from stmpl import predictor
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
