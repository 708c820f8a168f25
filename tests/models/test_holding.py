"""The held prior (models/holding.py): a near answer carried to the whole skin by the
tissue's linear FEM, against the float64 holding of the FEM wing, and its gradient.
"""

import numpy as np
import pytest
import torch

from fem.holding import Holding
from models.holding import HeldSkin
from stmpl.body import tube
from stmpl.pose import GAP_REACH


@pytest.fixture(scope="module")
def part():
    return tube(radius=0.03, length=0.08, n_around=12, n_along=6)


def test_the_held_answer_is_the_linear_fem_s_from_the_near_skin(part):
    """Two samples (two thicknesses, two places): on the vertices within reach of an object
    the answer is the given one, elsewhere the linear FEM's held answer within float32
    round-off, and the NumPy answer the same; a sample with no object near stays at rest; the
    answer is differentiable in the given skin.
    """
    x = part.vertices
    gap = np.full((3, part.n_vertices), GAP_REACH, np.float32)
    gap[0, (np.abs(x[:, 2] - 0.04) < 0.02) & (x[:, 0] > 0.015)] = -0.001
    gap[1, (np.abs(x[:, 2] - 0.04) < 0.02) & (x[:, 1] > 0.015)] = 0.004
    t = np.array([0.0075, 0.01, 0.0075], np.float32)[:, None].repeat(part.n_vertices, 1)
    rng = np.random.default_rng(0)
    r = torch.tensor(rng.normal(0, 1e-3, (3, part.n_vertices, 3)), requires_grad=True)
    skin = HeldSkin(part, "forearm")
    u = skin(r.float(), torch.from_numpy(gap), torch.from_numpy(t))
    for b in range(2):
        held = skin.held(gap[b], t[b])
        assert 0 < len(held) < part.n_vertices
        want = Holding(part, float(t[b, 0]), tissue="forearm").answer(held, r[b].detach().numpy())
        got = u[b].detach().numpy()
        peak = np.abs(want).max()
        np.testing.assert_allclose(got[held], want[held], atol=1e-5 * peak)
        assert np.abs(got - want).max() < 1e-3 * peak
        np.testing.assert_allclose(  # the FEM wing's NumPy answer is the same
            skin.answer(r[b].detach().float().numpy(), gap[b], t[b]), got, atol=1e-6 * peak
        )
        assert np.linalg.norm(got, axis=1)[np.setdiff1d(np.arange(len(got)), held)].max() > (
            0.05 * peak
        )
    assert float(u[2].abs().max()) == 0.0
    u[0].sum().backward()
    moved = r.grad[0].abs().sum(1).numpy() > 0
    np.testing.assert_array_equal(np.flatnonzero(moved), skin.held(gap[0], t[0]))


@pytest.mark.filterwarnings("ignore::stmpl.failures.OutsideEnvelope")
@pytest.mark.parametrize(
    "kind, options",
    [("gnn", {"latent": 16, "steps": 2}), ("uv_unet", {"size": 64, "width": 4, "depth": 3})],
)
def test_either_network_holds_its_near_answer(tiny_presses, kind, options):
    """Both networks given a pose take ``prior: held``: fitted to a set of the layered forearm
    (no training: weights stirred past the silent start), every answer off the vertices near
    the object is the linear FEM's with the answer near it held; unfitted, it is refused.
    """
    from fem.holding import Holding as Fixed
    from models.holding import fit_held
    from stmpl import predictor
    from stmpl.data.dataset import Dataset
    from stmpl.pipeline.evaluate import scenes_of

    ds = Dataset(tiny_presses)
    torch.manual_seed(0)
    p = predictor.create(kind, ds.part, {**options, "given": "pose", "prior": "held"})
    with torch.no_grad():
        for q in p.model.parameters():
            q.add_(0.1 * torch.randn_like(q))
    scenes, _ = scenes_of(ds, "test", given="pose")
    with pytest.raises(ValueError, match="needs the skin's linear FEM"):
        p.predict(scenes[0])
    fit_held(p, ds, progress=False)
    for s, d in zip(scenes, p.predict(scenes)):
        held = p.held_skin.held(s.pose.gap, s.thickness)
        want = Fixed(ds.part, s.thickness, tissue="forearm").answer(held, d.displacement)
        peak = np.abs(want).max()
        assert peak > 0 and np.abs(d.displacement - want).max() < 1e-3 * peak


@pytest.mark.filterwarnings("ignore::stmpl.failures.OutsideEnvelope")
@pytest.mark.parametrize(
    "kind, options",
    [("gnn", {"latent": 16, "steps": 2}), ("uv_unet", {"size": 64, "width": 4, "depth": 3})],
)
def test_a_closure_model_starts_from_the_linear_fem_s_closure(tiny_presses, kind, options):
    """``prior: closure``: either network given a pose and its motion, fitted and not trained
    (its last layer silent), answers the linear FEM's closure of the object (the set's friction
    and rounding, none here, analytic balls and disks: the checkpoint's record says so), within
    float32 round-off; the closure lies on the object's surface where the object pushes, so its
    peak is at least the object's depth into the rest skin, and a rounded object's reaches
    further. The network reads the closure as three more inputs (three more input channels'
    weights than the same network from the contact prior). Without the motion it is refused by
    name.
    """
    from fem.shapes import ROUNDING
    from models.holding import fit_held
    from stmpl import predictor
    from stmpl.data.dataset import Dataset
    from stmpl.pipeline.evaluate import scenes_of

    ds = Dataset(tiny_presses)
    options = {**options, "given": "pose", "prior": "closure"}
    with pytest.raises(ValueError, match="it needs motion: true"):
        predictor.create(kind, ds.part, options)
    p = predictor.create(kind, ds.part, {**options, "motion": True})
    contact = predictor.create(kind, ds.part, {**options, "motion": True, "prior": "contact"})
    first = 16 if kind == "gnn" else 4 * 4 * 4  # the first layer's outputs per input channel
    assert p.n_parameters() - contact.n_parameters() == 3 * first
    scenes, _ = scenes_of(ds, "test", given="pose", way=True)
    with pytest.raises(ValueError, match="prior: closure needs the skin's linear FEM"):
        p.predict(scenes[0])
    fit_held(p, ds, progress=False)
    assert p.meta["holding"]["friction"] == 0.0 and p.meta["holding"]["rounding_m"] == 0.0
    assert p.closure_options() == (0.0, 0.0, "least_energy")  # the rule it was fitted with
    record = p.meta["holding"]
    p.meta["holding"] = {k: v for k, v in record.items() if k != "contact_rule"}
    assert p.closure_options()[2] == "all_at_once"  # a model fitted before the rule was recorded
    p.meta["holding"] = record
    for s, d in zip(scenes, p.predict(scenes)):
        gap, way = s.pose.gap.astype(np.float32), s.pose.way.astype(np.float32)
        want = p.held_skin.closure(gap, way, s.thickness.astype(np.float32), 0.0, 0.0)
        peak = np.linalg.norm(want, axis=1).max()
        assert peak >= -gap.min() - 1e-6
        rounded = p.held_skin.closure(gap, way, s.thickness.astype(np.float32), 0.0, ROUNDING)
        assert np.linalg.norm(rounded, axis=1).max() > peak + 0.5 * ROUNDING
        np.testing.assert_allclose(d.displacement, want, atol=1e-5 * peak)


@pytest.mark.filterwarnings("ignore::stmpl.failures.OutsideEnvelope")
@pytest.mark.filterwarnings("ignore::stmpl.failures.ImpossibleAnswer")
@pytest.mark.parametrize("engine", ["default", "numpy"])
def test_a_held_gnn_runs_on_the_held_vertices_subgraph_as_on_the_whole_part(
    tiny_presses, tmp_path, monkeypatch, engine
):
    """With a held prior only the held vertices' answers are read, and no contact lies beyond
    them: the GNN runs on those vertices and ``steps`` hops more (fewer nodes than the part),
    and its displacement, contact forces and reaction are those of the network run on the
    whole part, in torch and in NumPy; in training (a relative loss), so are its loss and
    gradient.
    """
    from models.gnn import arrays as gnn_arrays
    from models.gnn import predictor as gnn_predictor
    from models.holding import fit_held
    from stmpl import predictor
    from stmpl.data.dataset import Dataset
    from stmpl.pipeline.evaluate import scenes_of

    ds = Dataset(tiny_presses)
    torch.manual_seed(0)
    p = predictor.create(
        "gnn",
        ds.part,
        {"latent": 16, "steps": 2, "given": "pose", "prior": "held", "loss": "relative"},
    )
    with torch.no_grad():
        for q in p.model.parameters():
            q.add_(0.1 * torch.randn_like(q))
    fit_held(p, ds, progress=False)
    if engine == "default":  # in training: the same loss and gradient on the subgraph
        from stmpl.pipeline.train import _split_tensors

        cfg = {"thickness_mm": None, "train_fraction": 1.0, "max_train": 0}
        t, g, target, _, _ = _split_tensors(ds, "train", cfg, "cpu", p)
        p.model.train()
        grads = []
        for held_only in (True, False):
            monkeypatch.setattr(type(p), "held_only", property(lambda self, h=held_only: h))
            p.model.zero_grad()
            loss = p.loss(t, g, target)
            loss.backward()
            grads.append(
                (float(loss.detach()), torch.cat([q.grad.ravel() for q in p.model.parameters()]))
            )
        monkeypatch.undo()
        assert grads[0][0] == pytest.approx(grads[1][0], rel=1e-5)
        torch.testing.assert_close(grads[0][1], grads[1][1], rtol=1e-4, atol=1e-6)
    p = predictor.read(p.save(tmp_path / "m.safetensors"), engine=engine)
    assert p.held_only
    scenes, _ = scenes_of(ds, "test", given="pose")
    module = gnn_arrays if engine == "numpy" else gnn_predictor
    sizes = []
    real = module.subgraph
    monkeypatch.setattr(
        module, "subgraph", lambda *a, **k: sizes.append(real(*a, **k)) or sizes[-1]
    )
    sub = p.predict(scenes)
    assert sizes and max(len(g.nodes) for g in sizes) < ds.part.n_vertices
    monkeypatch.setattr(type(p), "held_only", property(lambda self: False))
    whole = p.predict(scenes)
    for a, b in zip(sub, whole):
        peak = np.abs(b.displacement).max()
        assert peak > 0 and np.abs(a.displacement - b.displacement).max() <= 1e-5 * peak
        np.testing.assert_allclose(a.force, b.force, rtol=1e-4, atol=1e-9 * b.force.max())
        assert a.reaction == pytest.approx(b.reaction, rel=1e-4)


def test_the_pushed_skin_in_torch_is_the_fem_wing_s_and_its_gradient_stays_held(part):
    """:meth:`HeldSkin.pushed` (``held_answer: force``): an answer (no gradient, the compliance
    read in place) and a training step's (its rows gathered) are the FEM wing's
    :meth:`~fem.holding.HeldSkin.push` within float32 round-off; the gradient reaches the moves
    and the forces on the held DOFs alone; a sample with no object near stays at rest.
    """
    x = part.vertices
    gap = np.full((2, part.n_vertices), GAP_REACH, np.float32)
    gap[0, (np.abs(x[:, 2] - 0.04) < 0.02) & (x[:, 0] > 0.015)] = -0.001
    t = np.full((2, part.n_vertices), 0.0075, np.float32)
    rng = np.random.default_rng(1)
    r = torch.tensor(rng.normal(0, 1e-3, (2, part.n_vertices, 3)), dtype=torch.float32)
    forces = torch.tensor(rng.normal(0, 1e-3, (2, part.n_vertices, 3)), dtype=torch.float32)
    skin = HeldSkin(part, "forearm")
    g, th = torch.from_numpy(gap), torch.from_numpy(t)
    with torch.no_grad():
        answer = skin.pushed(r, forces, g, th)
    want = skin.push(r[0].numpy(), forces[0].numpy(), gap[0], t[0])
    peak = np.abs(want).max()
    np.testing.assert_allclose(answer[0].numpy(), want, atol=1e-5 * peak)
    assert float(answer[1].abs().max()) == 0.0
    r.requires_grad_(True)
    forces.requires_grad_(True)
    trained = skin.pushed(r, forces, g, th)
    np.testing.assert_allclose(trained[0].detach().numpy(), want, atol=1e-5 * peak)
    trained[0].sum().backward()
    held = skin.held(gap[0], t[0])
    for grad in (r.grad, forces.grad):
        np.testing.assert_array_equal(np.flatnonzero(grad[0].abs().sum(1).numpy() > 0), held)
        assert float(grad[1].abs().max()) == 0.0


@pytest.mark.filterwarnings("ignore::stmpl.failures.OutsideEnvelope")
@pytest.mark.filterwarnings("ignore::stmpl.failures.ImpossibleAnswer")  # the stirred weights'
@pytest.mark.parametrize("engine", ["default", "numpy"])
def test_a_force_answering_closure_gnn_starts_from_the_closure(tiny_presses, tmp_path, engine):
    """``held_answer: force``: a GNN with the closure prior answers three more channels (the
    forces on the held skin); fitted and not trained (its last layer silent) it answers the
    linear FEM's closure, in torch and in NumPy; stirred, both engines answer alike. Without
    the closure prior, or with another word, it is refused by name.
    """
    from models.holding import fit_held
    from stmpl import predictor
    from stmpl.data.dataset import Dataset
    from stmpl.pipeline.evaluate import scenes_of

    ds = Dataset(tiny_presses)
    options = {"latent": 16, "steps": 2, "given": "pose", "motion": True, "prior": "closure"}
    with pytest.raises(ValueError, match="it takes prior: closure"):
        predictor.create("gnn", ds.part, {**options, "prior": "held", "held_answer": "force"})
    with pytest.raises(ValueError, match="held_answer must be one of"):
        predictor.create("gnn", ds.part, {**options, "held_answer": "forces"})
    torch.manual_seed(0)
    p = predictor.create("gnn", ds.part, {**options, "held_answer": "force"})
    assert p.out_channels == 8
    fit_held(p, ds, progress=False)
    scenes, _ = scenes_of(ds, "test", given="pose", way=True)
    q = predictor.read(p.save(tmp_path / "silent.safetensors"), engine=engine)
    for s, d in zip(scenes, q.predict(scenes)):
        gap, way = s.pose.gap.astype(np.float32), s.pose.way.astype(np.float32)
        want = p.held_skin.closure(gap, way, s.thickness.astype(np.float32), 0.0, 0.0)
        peak = np.linalg.norm(want, axis=1).max()
        assert peak > 0
        np.testing.assert_allclose(d.displacement, want, atol=1e-5 * peak)
    with torch.no_grad():
        for w in p.model.parameters():
            w.add_(0.1 * torch.randn_like(w))
    q = predictor.read(p.save(tmp_path / "stirred.safetensors"), engine=engine)
    for a, b in zip(p.predict(scenes), q.predict(scenes)):
        peak = np.abs(a.displacement).max()
        assert np.abs(a.displacement - b.displacement).max() <= 1e-5 * peak
    s = scenes[0]
    closure = p.held_skin.closure(
        s.pose.gap.astype(np.float32), s.pose.way.astype(np.float32), s.thickness, 0.0, 0.0
    )
    assert np.abs(q.predict(s).displacement - closure).max() > 0.01 * np.abs(closure).max()
