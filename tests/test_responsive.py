"""A press at a new place is answered at once by a stand-in, marked so, while the model is
prepared for it; then the model answers.
"""

import numpy as np
import pytest

from stmpl import predictor
from stmpl.pipeline.evaluate import scenes_of
from stmpl.responsive import Responsive


def test_a_new_place_is_answered_by_the_stand_in_until_the_model_is_ready(
    ds, make, tmp_path, monkeypatch
):
    monkeypatch.setenv("STMPL_CACHE_DIR", str(tmp_path / "fitted"))
    p = predictor.create(
        "gnn", ds.part, {"latent": 16, "steps": 2, "prior": "linear", "operator": "on_demand"}
    )
    p.fit(ds, progress=False)
    path = p.save(tmp_path / "g.safetensors")
    monkeypatch.setenv("STMPL_CACHE_DIR", str(tmp_path / "empty"))  # no column solved yet
    model, naive = predictor.read(path), make("naive", ds)
    scene = scenes_of(ds, "test", limit=1)[0][0]
    assert model.missing(scene) > 0
    live = Responsive(model, naive)

    first = live.predict(scene)  # at once: the stand-in's, said so
    assert first.info["stand_in"] == {"for": "gnn", "by": "naive"}
    np.testing.assert_array_equal(first.displacement, naive.predict(scene).displacement)
    assert live.wait(120) and not live.errors
    assert model.missing(scene) == 0

    second = live.predict(scene)  # the model's own
    assert "stand_in" not in second.info and second.info["predictor"] == "gnn"
    np.testing.assert_array_equal(second.displacement, model.predict(scene).displacement)
    fitted = p.predict(scene).displacement  # its columns solved on the whole part, not a patch
    peak = np.linalg.norm(fitted, axis=1).max()
    assert np.linalg.norm(second.displacement - fitted, axis=1).max() < 0.01 * peak


def test_a_stand_in_that_would_wait_too_is_refused(ds):
    class Waiting:  # a predictor that would compute first wherever it is asked
        name = "waiting"

        def missing(self, scene):
            return 1

    scene = scenes_of(ds, "test", limit=1)[0][0]
    with pytest.raises(ValueError, match="cannot answer at once"):
        Responsive(Waiting(), Waiting()).predict(scene)
    with pytest.raises(TypeError, match="one Scene"):
        Responsive(Waiting(), Waiting()).predict([scene])
