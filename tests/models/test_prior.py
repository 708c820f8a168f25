"""The linear FEM as a prior: untrained, a prior model answers exactly the linear FEM."""

import numpy as np
import pytest

from models.linear.operator import needed_columns
from stmpl import predictor
from stmpl.pipeline.evaluate import scenes_of

TINY_MODELS = {
    "naive": {},
    "linear": {},
    "uv_unet": {"size": 64, "width": 4, "depth": 3},
    "gnn": {"latent": 16, "steps": 2},
}


@pytest.mark.parametrize("kind", ["gnn", "uv_unet"])
def test_linear_prior_starts_at_the_linear_fem(kind, ds, tmp_path, make):
    """``prior: linear``: untrained, the network's output is silent and the predictor answers
    exactly the linear FEM (for the UNet without a seam gap); its checkpoint carries the
    operator (it loads with nothing else), and an unknown prior is refused.
    """
    p = make(f"{kind}/prior", ds)
    lin = make("linear", ds)
    scenes, _ = scenes_of(ds, "test", limit=3)
    for a, b in zip(p.predict(scenes), lin.predict(scenes)):
        np.testing.assert_allclose(a.displacement, b.displacement, rtol=1e-5, atol=1e-9)
    q = predictor.read(p.save(tmp_path / "g.safetensors"))
    assert q.model.prior.index.shape == p.model.prior.index.shape
    for a, b in zip(p.predict(scenes), q.predict(scenes)):
        np.testing.assert_array_equal(a.displacement, b.displacement)
    if kind == "uv_unet":
        import torch

        t = torch.tensor(np.stack([s.thickness for s in scenes]), dtype=torch.float32)
        f = torch.tensor(np.stack([s.force for s in scenes]), dtype=torch.float32)
        c = p.corner_displacement(t, f)  # (B, corners, 3)
        np.testing.assert_allclose(
            c,
            np.stack([d.displacement for d in lin.predict(scenes)])[:, ds.part.uv_vertex],
            rtol=1e-5,
            atol=1e-9,
        )
    with pytest.raises(ValueError, match="prior must be one of"):
        predictor.create(kind, ds.part, {**TINY_MODELS[kind], "prior": "fem"})


@pytest.mark.parametrize("kind", ["gnn", "uv_unet"])
def test_on_demand_prior_travels_as_its_set_up(kind, ds, tmp_path, make, monkeypatch):
    """``operator: on_demand``: the prior is the same linear FEM, solved for the columns the
    scenes load; the checkpoint holds only its set-up and levels, and a loaded model rebuilds it
    (from the disk cache) to the same answers.
    """
    monkeypatch.setenv("STMPL_CACHE_DIR", str(tmp_path))
    p = predictor.create(
        kind, ds.part, {**TINY_MODELS[kind], "prior": "linear", "operator": "on_demand"}
    )
    p.fit(ds, progress=False)
    lin = make("linear", ds)
    scenes, _ = scenes_of(ds, "test", limit=3)
    for a, b in zip(p.predict(scenes), lin.predict(scenes)):
        peak = np.linalg.norm(b.displacement, axis=1).max()
        assert np.linalg.norm(a.displacement - b.displacement, axis=1).max() < 0.01 * peak
    q = predictor.read(p.save(tmp_path / "g.safetensors"))
    assert q.model.prior.on_demand and q.model.prior.index.shape[1] == 0
    for a, b in zip(p.predict(scenes), q.predict(scenes)):
        np.testing.assert_allclose(a.displacement, b.displacement, rtol=1e-5, atol=1e-12)


def test_a_batch_in_chunks_solves_its_columns_at_once(ds, tmp_path, monkeypatch):
    """A batch answered chunk by chunk (:meth:`LearnedPredictor.chunk`) solves the columns of
    all its scenes first, one solve per level, not one per chunk; the answers are those of the
    batch in one call.
    """
    import models.trained

    monkeypatch.setenv("STMPL_CACHE_DIR", str(tmp_path / "fit"))
    p = predictor.create(
        "gnn", ds.part, {**TINY_MODELS["gnn"], "prior": "linear", "operator": "on_demand"}
    )
    p.fit(ds, progress=False)
    path = p.save(tmp_path / "g.safetensors")
    scenes = scenes_of(ds, "train")[0]
    scenes = [s for s in scenes if s.thickness[0] == scenes[0].thickness[0]][:6]  # one layer
    assert len(scenes) >= 5
    whole = [d.displacement for d in p.predict(scenes)]
    monkeypatch.setenv("STMPL_CACHE_DIR", str(tmp_path / "empty"))  # nothing solved
    q = predictor.read(path)
    monkeypatch.setattr(models.trained, "CHUNK_VERTICES", 2 * ds.part.n_vertices)
    assert q.chunk() == 2 and all(q.missing(s) > 0 for s in scenes)
    answers = q.predict(scenes)
    op = q.model.prior
    t = np.stack([s.thickness for s in scenes]).astype(np.float32)
    f = np.stack([s.force for s in scenes]).astype(np.float32)
    levels = sum(1 for c in needed_columns(op, t, f) if len(c))
    assert len(op.store.log) == levels  # one solve per level for the batch, not per chunk
    assert all(q.missing(s) == 0 for s in scenes)
    for a, b in zip(answers, whole):
        peak = np.linalg.norm(b, axis=1).max()
        assert np.linalg.norm(a.displacement - b, axis=1).max() < 0.01 * peak
