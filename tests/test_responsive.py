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
    with pytest.raises(ValueError, match=r"no stand-in \(waiting\) can answer at once"):
        Responsive(Waiting(), Waiting()).predict(scene)
    with pytest.raises(TypeError, match="one Scene"):
        Responsive(Waiting(), Waiting()).predict([scene])


class _Fake:
    """A predictor that answers at once where it is ready, and gets ready by answering once
    (slowly, once ``gate`` opens); what it answered with is its name in ``info``.
    """

    def __init__(self, name, ready=True, fails=False):
        import threading

        self.name, self.ready, self.fails = name, ready, fails
        self.gate = threading.Event()
        self.gate.set()

    def missing(self, scene):
        return 0 if self.ready else 1

    def predict(self, scene):
        from stmpl.scene import Deformation

        if not self.ready:
            self.gate.wait(30)
            if self.fails:
                raise RuntimeError("no room for the columns")
            self.ready = True
        u = np.zeros((scene.part.n_vertices, 3))
        return Deformation(scene, u, info={"predictor": self.name})


def test_the_first_stand_in_that_answers_at_once_answers_and_the_callbacks_are_called(ds):
    import threading

    scene = scenes_of(ds, "test", limit=1)[0][0]
    model, busy, quick = _Fake("model", ready=False), _Fake("busy", ready=False), _Fake("quick")
    model.gate.clear()
    ready, said = threading.Event(), []
    live = Responsive(model, [busy, quick], on_ready=ready.set, on_error=said.append)
    d = live.predict(scene)
    assert d.info["stand_in"] == {"for": "model", "by": "quick"}  # busy would have to compute
    assert live.missing(scene) == 1  # being prepared: no stand-in for another meanwhile
    other = Responsive(_Fake("other", ready=False), [live, quick])
    assert other.predict(scene).info["stand_in"]["by"] == "quick"
    model.gate.set()
    assert ready.wait(30) and live.wait(30) and not said
    assert live.missing(scene) == 0 and "stand_in" not in live.predict(scene).info
    failing = _Fake("failing", ready=False, fails=True)
    live = Responsive(failing, quick, on_error=said.append)
    live.predict(scene)
    assert live.wait(30) and said == ["failing could not prepare a place: no room for the columns"]


def test_with_wait_the_model_answers_itself_where_no_stand_in_can():
    from stmpl.body.primitives import tube
    from stmpl.scene import Scene

    part = tube(n_around=8, n_along=6)
    scene = Scene(part, np.full(part.n_vertices, 0.005), np.full(part.n_vertices, 0.01))
    model = _Fake("model", ready=False)
    d = Responsive(model, _Fake("slow", ready=False), wait=True).predict(scene)
    assert d.info == {"predictor": "model"} and model.ready


def test_the_model_and_its_stand_ins_load_their_compiled_code_before_the_first_press():
    """A background solve that loads compiled code holds the GIL while a press waits (0.4-0.6 s
    once per drag, measured by benchmarks/first_touch.py): a Responsive loads it first.
    """
    loaded = []

    class Loading(_Fake):
        def load_kernels(self):
            loaded.append(self.name)

    Responsive(Loading("model"), [Loading("quick"), _Fake("bare")])
    assert loaded == ["model", "quick"]
