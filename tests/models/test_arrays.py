"""A trained GNN answered with NumPy alone (``engine="numpy"``): the torch predictor's answers
to float32 rounding, for every option the zoo's and the pose models use, at both fidelities,
on the model's own body and another body of its mesh; no torch imported; the engines that
cannot be are refused by name.
"""

import subprocess
import sys
import warnings

import numpy as np
import pytest
import torch

from stmpl import loads, predictor, tissue
from stmpl.scene import Scene
from tests.conftest import TINY_MODELS, pressed_ball

VARIANTS = {
    "force": {},
    "per_newton": {"per_newton": True},
    "stored prior": {"per_newton": True, "prior": "linear", "loss": "relative"},
    "on-demand prior of every body": {
        "per_newton": True,
        "prior": "linear",
        "operator": "on_demand",
        "geometry": True,
    },
}


def _shaken(p, seed: int = 0):
    """The predictor with weights far from their start (a silent last layer would hide the
    network), as training leaves them.
    """
    g = torch.Generator().manual_seed(seed)
    with torch.no_grad():
        for w in p.model.net.parameters():
            w.copy_(torch.randn(w.shape, generator=g) * 0.4)
    return p


def _scenes(part, other=None):
    """A disk on the part's middle and a light one near its rim, on ``part`` (and ``other``)."""
    t = tissue.constant(part, 0.0075)
    middle = int(np.argmin(np.abs(part.axial - np.median(part.axial))))
    rim = int(np.argmin(part.rim_distance + 1e3 * (part.rim_distance < 0.03)))
    out = [
        Scene.from_load(part, t, loads.disk(part, middle, radius=0.03, total=0.2)),
        Scene.from_load(part, t, loads.disk(part, rim, radius=0.02, total=0.05)),
    ]
    if other is not None:
        out.append(Scene.from_load(other, t, loads.disk(other, middle, radius=0.03, total=0.2)))
    return out


def _close(a, b, scale):
    assert np.abs(np.asarray(a) - np.asarray(b)).max() <= 1e-5 * scale


@pytest.mark.parametrize("variant", list(VARIANTS))
@pytest.mark.parametrize("fidelity", ["full", "auto"])
def test_numpy_answers_as_torch_does(ds, tmp_path, variant, fidelity):
    torch.manual_seed(0)
    options = {**TINY_MODELS["gnn"], **VARIANTS[variant]}
    p = predictor.create("gnn", ds.part, options, fidelity=fidelity)
    if hasattr(p, "fit") and options.get("prior") == "linear":
        p.fit(ds, progress=False)
    path = _shaken(p).save(tmp_path / "m.safetensors")
    torched = predictor.read(path, fidelity=fidelity)
    light = predictor.read(path, engine="numpy", fidelity=fidelity)
    assert type(light).__name__ == "GNNArrays" and light.takes == torched.takes
    other = None
    if options.get("geometry"):  # another body of the mesh: the tube 10 % wider
        centre = ds.part.vertices.mean(0)
        other = ds.part.with_vertices(centre + 1.1 * (ds.part.vertices - centre))
    scenes = _scenes(ds.part, other)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        want = torched.predict(scenes)
        got = light.predict(scenes)
        one = light.predict(scenes[0])
    deepest = max(np.abs(d.displacement).max() for d in want)
    assert deepest > 1e-6  # the network moves the skin
    for w, g in zip(want, got):
        _close(g.displacement, w.displacement, deepest)
        assert g.info["envelope"] == w.info["envelope"]
        assert g.info["physical"] == w.info["physical"]
    _close(one.displacement, want[0].displacement, deepest)  # alone as in a batch


@pytest.mark.parametrize("prior", ["none", "contact"])
@pytest.mark.parametrize("fidelity", ["full", "auto"])
def test_a_pose_model_answers_its_pressures_and_reaction_as_torch_does(
    ds, tmp_path, prior, fidelity
):
    torch.manual_seed(0)
    options = {**TINY_MODELS["gnn"], "given": "pose", "prior": prior}
    path = _shaken(predictor.create("gnn", ds.part, options)).save(tmp_path / "m.safetensors")
    scene = pressed_ball(ds.part)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        want = predictor.read(path, fidelity=fidelity).predict(scene)
        got = predictor.read(path, engine="numpy", fidelity=fidelity).predict(scene)
    _close(got.displacement, want.displacement, np.abs(want.displacement).max())
    np.testing.assert_allclose(got.force, want.force, rtol=1e-4, atol=1e-9 * want.force.max())
    assert got.reaction == pytest.approx(want.reaction, rel=1e-4)
    assert want.force.max() > 0 and want.reaction != 0


def test_the_numpy_engine_imports_no_torch(ds, tmp_path):
    torch.manual_seed(0)
    p = predictor.create("gnn", ds.part, {**TINY_MODELS["gnn"], "per_newton": True})
    path = _shaken(p).save(tmp_path / "m.safetensors")
    code = (
        "import sys, warnings; warnings.simplefilter('ignore')\n"
        "from stmpl import loads, predictor, tissue\n"
        "from stmpl.scene import Scene\n"
        f"p = predictor.read({str(path)!r}, engine='auto')\n"
        "part = p.part\n"
        "s = Scene.from_load(part, tissue.constant(part, 0.0075), loads.disk(part, 5, 0.03, 0.2))\n"
        "d = p.predict(s)\n"
        "print(type(p).__name__, 'torch' in sys.modules, float(abs(d.displacement).max()))\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    name, imported, deepest = out.stdout.split()
    assert name == "GNNArrays" and imported == "False" and float(deepest) > 0


def test_engines_that_cannot_be_are_refused_by_name(ds, tmp_path):
    naive = predictor.create("naive", ds.part, {}).save(tmp_path / "naive.safetensors")
    gnn = predictor.create("gnn", ds.part, TINY_MODELS["gnn"]).save(tmp_path / "gnn.safetensors")
    with pytest.raises(ValueError, match="a naive model has no NumPy inference"):
        predictor.read(naive, engine="numpy")
    assert type(predictor.read(naive, engine="auto")).__name__ == "NaivePredictor"
    with pytest.raises(ValueError, match="engine must be one of"):
        predictor.read(gnn, engine="onnx")
    with pytest.raises(ValueError, match="answers on the CPU, not on 'cuda'"):
        predictor.read(gnn, engine="numpy", device="cuda")
    assert type(predictor.read(gnn, engine="auto")).__name__ == "GNNArrays"


def test_a_batch_in_chunks_answers_as_one_its_columns_solved_ahead(ds, tmp_path, monkeypatch):
    import models.trained

    torch.manual_seed(0)
    options = {**TINY_MODELS["gnn"], **VARIANTS["on-demand prior of every body"]}
    p = predictor.create("gnn", ds.part, options)
    p.fit(ds, progress=False)
    path = _shaken(p).save(tmp_path / "m.safetensors")
    scenes = _scenes(ds.part)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        whole = predictor.read(path, engine="numpy").predict(scenes)
        light = predictor.read(path, engine="numpy")
        calls = []
        real = light.ahead
        light.ahead = lambda batch: calls.append(len(batch)) or real(batch)
        monkeypatch.setattr(models.trained, "CHUNK_VERTICES", ds.part.n_vertices)  # 1 a call
        chunked = light.predict(scenes)
    assert calls == [len(scenes)]
    for a, b in zip(whole, chunked):
        _close(b.displacement, a.displacement, np.abs(a.displacement).max())  # float32 sums


def test_an_answer_runs_on_one_blas_thread_and_gives_the_rest_back(ds, tmp_path, monkeypatch):
    from models.gnn import arrays

    torch.manual_seed(0)
    path = predictor.create("gnn", ds.part, TINY_MODELS["gnn"]).save(tmp_path / "m.safetensors")
    light = predictor.read(path, engine="numpy")

    def threads():
        return [i["num_threads"] for i in arrays.blas().info() if i["user_api"] == "blas"]

    before, seen = threads(), []
    real = arrays.GraphNetArrays.__call__
    monkeypatch.setattr(
        arrays.GraphNetArrays, "__call__", lambda *a, **k: seen.append(threads()) or real(*a, **k)
    )
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        light.predict(_scenes(ds.part))
    assert seen and all(t == [1] * len(before) for t in seen)
    assert threads() == before
