"""The contract every predictor keeps: shapes, batch = single, determinism, bad input."""

import numpy as np
import pytest

from stmpl import predictor
from stmpl.body.primitives import tube
from stmpl.evaluate import scenes_of
from stmpl.scene import Deformation, Scene


def _make(name, ds):
    if name == "fem":
        return predictor.create("fem", res={"subdivisions": 1, "layers": 1, "order": 1})
    return predictor.REGISTRY[name](ds.part)


@pytest.fixture(scope="module")
def ds(tiny_dataset):
    from stmpl.data import Dataset

    return Dataset(tiny_dataset)


@pytest.mark.parametrize("name", ["fem", "naive"])
def test_contract(name, ds):
    p = _make(name, ds)
    scenes, _ = scenes_of(ds, "train", limit=3)
    one = p.predict(scenes[0])
    assert isinstance(one, Deformation) and one.displacement.shape == (ds.part.n_vertices, 3)
    assert one.info["predictor"] == name and one.info["seconds"] >= 0
    many = p.predict(scenes)
    assert isinstance(many, list) and len(many) == 3
    np.testing.assert_allclose(many[0].displacement, one.displacement, atol=1e-9)
    again = p.predict(scenes)
    for a, b in zip(many, again):
        np.testing.assert_array_equal(a.displacement, b.displacement)
    with pytest.raises(ValueError, match="at least one"):
        p.predict([])
    with pytest.raises(TypeError, match="not a Scene"):
        p.predict([scenes[0], "scene"])


def test_fem_predictor_reproduces_the_dataset(ds):
    scenes, truth = scenes_of(ds, "train", limit=4)
    p = predictor.create("fem", res=dict(ds.card["config"]["resolution"]))
    levels = ds.card["config"]["forces"]
    for s, u in zip(scenes, truth):
        k = levels.index(s.meta["total"]) + 1
        p.levels = k       # the dataset reached this level by k continuation steps
        d = p.predict(s)
        np.testing.assert_allclose(d.displacement, u, atol=1e-7)
        assert d.info["ok"] and d.info["iterations"] >= 1


def test_fem_predictor_raises_on_failure(ds):
    s = Scene(ds.part, np.full(ds.part.n_vertices, 0.005),
              np.where(np.arange(ds.part.n_vertices) == 40, 15.0, 0.0))
    with pytest.raises(predictor.FEMFailed, match="FEM failed"):
        predictor.create("fem", res={"subdivisions": 0, "layers": 1, "order": 1},
                         options=None).predict(s)


def test_learned_predictor_refuses_another_part(ds):
    p = predictor.REGISTRY["naive"](ds.part)
    other = tube(n_around=8, n_along=4)
    s = Scene(other, np.full(other.n_vertices, 0.005), np.zeros(other.n_vertices))
    with pytest.raises(ValueError, match="another body part"):
        p.predict(s)


def test_registry():
    assert {"fem", "naive"} <= set(predictor.names())
    with pytest.raises(ValueError, match="unknown predictor"):
        predictor.create("oracle")
    with pytest.raises(ValueError, match="unknown naive model options"):
        predictor.REGISTRY["naive"](tube(), {"depth": 3})
