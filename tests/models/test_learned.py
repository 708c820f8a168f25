"""The learned machinery every model shares: the relative loss and per-newton outputs."""

import numpy as np
import pytest

from models import features
from stmpl import predictor
from stmpl.pipeline.evaluate import scenes_of
from stmpl.pose import Pose
from stmpl.scene import Scene
from tests.conftest import pressed_ball

TINY_MODELS = {
    "naive": {},
    "linear": {},
    "uv_unet": {"size": 64, "width": 4, "depth": 3},
    "gnn": {"latent": 16, "steps": 2},
}


def test_relative_loss_is_the_relative_mee(ds):
    """``loss: relative`` is each sample's mean Euclidean error over its peak: a prediction 10 %
    too large everywhere scores 0.1 * mean |u| / max |u|; ``pooled`` sums both over the batch
    first; an unknown loss is refused.
    """
    import torch

    p = predictor.create(
        "gnn", ds.part, {**TINY_MODELS["gnn"], "per_newton": True, "loss": "relative"}
    )
    scenes, truth = scenes_of(ds, "test", limit=2)
    t = torch.tensor(np.stack([s.thickness for s in scenes]), dtype=torch.float32)
    f = torch.tensor(np.stack([s.force for s in scenes]), dtype=torch.float32)
    u = torch.tensor(truth, dtype=torch.float32)
    p.raw = lambda thickness, force, body=None, base=None: p.normalised(1.1 * u, force)
    mag = np.linalg.norm(truth, axis=-1)
    expected = np.mean(0.1 * mag.mean(-1) / mag.max(-1))
    assert float(p.loss(t, f, u)) == pytest.approx(expected, rel=2e-3)
    # pooled: the batch's errors over its peaks, summed first (a heavier press weighs more)
    # (the second sample three times as deep and 30 % off, where relative sees only 10 and 30 %)
    u[1] *= 3.0
    mag[1] *= 3.0
    over = torch.tensor([1.1, 1.3])[:, None, None]
    p.raw = lambda thickness, force, body=None, base=None: p.normalised(over * u, force)
    err = np.array([0.1, 0.3])[:, None] * mag
    p.config["loss"] = "pooled"
    pooled = err.mean(-1).sum() / mag.max(-1).sum()
    assert float(p.loss(t, f, u)) == pytest.approx(pooled, rel=2e-3)
    p.config["loss"] = "relative"
    relative = np.mean(err.mean(-1) / mag.max(-1))
    assert float(p.loss(t, f, u)) == pytest.approx(relative, rel=2e-3)
    assert pooled > 1.1 * relative
    with pytest.raises(ValueError, match="loss must be one of"):
        predictor.create("gnn", ds.part, {**TINY_MODELS["gnn"], "loss": "l1"})


@pytest.mark.parametrize("name", ["uv_unet/per_newton", "gnn/per_newton"])
def test_per_newton_models_scale_with_the_total_force(name, ds, make):
    """A per-newton model predicts u / F_total from the force pattern and the total: an unloaded
    scene gets exactly zero, and its target is the displacement per newton.
    """
    import torch

    p = make(name, ds)
    scenes, truth = scenes_of(ds, "test", limit=1)
    s = scenes[0]
    zero = p.predict(Scene(s.part, s.thickness, np.zeros_like(s.force)))
    assert np.all(zero.displacement == 0.0)
    f = torch.tensor(s.force[None], dtype=torch.float32)
    u = torch.tensor(truth[:1], dtype=torch.float32)
    np.testing.assert_allclose(
        p.normalised(u, f).numpy() * s.force.sum() * p.scale, truth[:1], rtol=1e-4, atol=1e-9
    )
    raw = p.raw(torch.tensor(s.thickness[None], dtype=torch.float32), f)
    np.testing.assert_allclose(
        p.forward(torch.tensor(s.thickness[None], dtype=torch.float32), f).detach().numpy(),
        raw.detach().numpy() * s.force.sum(),
        rtol=1e-5,
    )


def test_a_model_of_the_left_arm_answers_the_right_in_the_mirror(anny_body):
    """The zoo's plain-arm GNN on anny's right arm: the mirror image of its answer on the left
    (exactly), and within 1 % of the FEM solved on the right arm itself.
    """
    import warnings

    from fem.predictor import FEMPredictor
    from stmpl import loads, tissue
    from stmpl.metrics import sample_metrics
    from stmpl.pipeline import zoo
    from stmpl.scene import Scene

    p = zoo.read("gnn_arm")
    left, right = anny_body.part("left_arm"), anny_body.part("right_arm")
    s_r, s_l = (
        Scene(a, tissue.constant(a, 7.5e-3), loads.disk(a, 300, 0.02, 0.2).force)
        for a in (right, left)
    )
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        d_r, d_l = p.predict(s_r), p.predict(s_l)
    assert d_r.info["mirrored"] and d_r.scene is s_r
    np.testing.assert_allclose(d_r.displacement, d_l.displacement * [-1, 1, 1], atol=1e-12)
    fem = FEMPredictor().predict(s_r)
    assert sample_metrics(fem.displacement, d_r.displacement)["rel_mee"] < 1.0


@pytest.mark.parametrize("name", ["gnn/prior", "uv_unet/prior"])
@pytest.mark.parametrize("fidelity", ["full", "auto"])
def test_a_batch_answered_in_chunks_is_answered_as_one(name, fidelity, ds, make, monkeypatch):
    """A batch bigger than a network call takes (:meth:`LearnedPredictor.chunk`) is answered
    chunk by chunk, in order, with the same answers as in one call.
    """
    import models.trained

    p = make(name, ds).with_fidelity(fidelity)
    scenes = scenes_of(ds, "test", limit=5)[0]
    monkeypatch.setattr(models.trained, "CHUNK_SCENES", 64)
    monkeypatch.setattr(models.trained, "CHUNK_VERTICES", 64 * ds.part.n_vertices)
    whole = [d.displacement for d in p.predict(scenes)]
    monkeypatch.setattr(models.trained, "CHUNK_SCENES", 2)
    monkeypatch.setattr(models.trained, "CHUNK_VERTICES", 2 * ds.part.n_vertices)
    assert p.chunk() == 2
    for a, b in zip(p.predict(scenes), whole):
        np.testing.assert_allclose(a.displacement, b, rtol=1e-5, atol=1e-10)


@pytest.mark.parametrize("kind", ["gnn", "uv_unet"])
def test_a_model_given_a_pose_answers_the_force_near_the_object_and_its_reaction(
    ds, tmp_path, kind
):
    """Option ``given: pose``: the model reads the gap field, and its answer carries a contact
    force only near the object (where its pressure output is positive) and the reaction, its
    push output summed there; the option travels in the checkpoint; the combinations that
    cannot be are refused by name.
    """
    import torch

    from models.features import CONTACT_BAND, CONTACT_TAPER, PRESSURE_OUT_SCALE
    from stmpl import tissue
    from stmpl.contact import objects
    from stmpl.contact.posing import posed

    torch.manual_seed(0)
    p = predictor.create(kind, ds.part, {**TINY_MODELS[kind], "given": "pose"})
    ball = objects.sphere(0.008)
    at = int(np.argmax(ds.part.rim_distance))
    pose = objects.press(ds.part, ball, at, depth=3e-3)
    scene = posed(ds.part, tissue.constant(ds.part, 0.0075), ball, pose)
    d = p.predict(scene)
    gap = scene.pose.gap
    reached = gap < CONTACT_BAND + CONTACT_TAPER  # the band and its taper
    assert not d.force[~reached].any() and d.force.min() >= 0
    t, g = (torch.tensor(x[None], dtype=torch.float32) for x in (scene.thickness, gap))
    with torch.no_grad():
        out = p.forward(t, g)[0].double().numpy() * PRESSURE_OUT_SCALE  # pressure, push: Pa
    share = np.clip((CONTACT_BAND + CONTACT_TAPER - gap) / CONTACT_TAPER, 0, 1)
    assert np.all(share[gap <= CONTACT_BAND] == 1) and np.any((share > 0) & (share < 1))
    area = ds.part.vertex_areas
    np.testing.assert_allclose(d.force, np.maximum(out[:, 3], 0) * share * area)
    assert d.reaction == pytest.approx(float(np.sum(out[:, 4] * share * area)), rel=1e-6)
    q = predictor.read(p.save(tmp_path / "m.safetensors"))
    assert q.takes == ("pose",)
    np.testing.assert_allclose(q.predict(scene).displacement, d.displacement, atol=1e-9)
    np.testing.assert_allclose(q.predict(scene).force, d.force, rtol=1e-6)
    for options, message in [
        ({"given": "pose", "per_newton": True}, "knows no force to answer per newton"),
        ({"given": "pose", "prior": "linear"}, "a model given a pose takes prior: none"),
        ({"prior": "contact"}, "a model given a force takes prior: none or linear"),
        ({"given": "both"}, "given must be one of"),
    ]:
        with pytest.raises(ValueError, match=message):
            predictor.create(kind, ds.part, {**TINY_MODELS[kind], **options})
    with pytest.raises(ValueError, match="the naive model takes a force only"):
        predictor.create("naive", ds.part, {"given": "pose"})


@pytest.mark.parametrize("kind", ["gnn", "uv_unet"])
def test_the_contact_prior_lays_the_skin_inside_an_object_on_its_surface(ds, kind):
    """Option ``prior: contact``: the answer is the network's plus each rest vertex inside the
    object moved out along its inward normal by how deep it lies (the gap), and nothing more
    elsewhere; the network starts silent, its pressures at a light touch's.
    """
    import torch

    from models.prior import PRESSURE_START

    torch.manual_seed(0)
    p = predictor.create(kind, ds.part, {**TINY_MODELS[kind], "given": "pose", "prior": "contact"})
    scene = pressed_ball(ds.part)
    gap = scene.pose.gap
    p.model.eval()
    assert (gap < 0).sum() >= 3  # the ball reaches into a few vertices
    t, g = (torch.tensor(x[None], dtype=torch.float32) for x in (scene.thickness, gap))
    with torch.no_grad():
        a = p.forward(t, g)[0].double().numpy()
    moved = ds.part.normals * np.minimum(gap, 0.0)[:, None]  # m, into the skin
    np.testing.assert_allclose(a[:, :3] * p.scale, moved, atol=1e-8)  # the network starts silent
    np.testing.assert_allclose(a[:, 3:], PRESSURE_START, rtol=1e-6)  # and a light touch's pressure
    assert np.einsum("ij,ij->i", moved, ds.part.normals)[gap < 0].max() < 0  # inward


@pytest.mark.parametrize("kind", ["gnn", "uv_unet"])
def test_a_model_with_the_contact_prior_learns_only_what_the_prior_leaves(ds, kind):
    """Training with ``prior: contact`` scores the whole answer, prior included: the model's own
    answer as the target costs (next to) nothing, that answer less the prior costs as much as
    the prior's share of the peak, over the whole part and where the object presses.
    """
    import torch

    from stmpl import tissue
    from stmpl.contact import objects
    from stmpl.contact.posing import posed

    torch.manual_seed(0)
    options = {**TINY_MODELS[kind], "given": "pose", "prior": "contact", "loss": "relative"}
    p = predictor.create(kind, ds.part, options)
    with torch.no_grad():  # a network that has learned something: it starts silent
        for w in p.model.parameters():
            w.add_(0.05 * torch.randn_like(w))
    p.model.eval()
    p.reaction_loss = lambda *args: 0.0  # the reaction's term has a test of its own
    ball = objects.sphere(0.05)
    far = ds.part.rim_distance.copy()
    far[ds.part.seam_vertices] = 0.0  # off the chart's seam: each vertex one corner
    at = int(np.argmax(far))
    scene = posed(
        ds.part,
        tissue.constant(ds.part, 0.0075),
        ball,
        objects.press(ds.part, ball, at, depth=8e-3),
    )
    t, g = (torch.tensor(x[None], dtype=torch.float32) for x in (scene.thickness, scene.pose.gap))
    with torch.no_grad():
        own = p.forward(t, g)
        target = torch.cat([own[..., :3] * p.scale, own[..., 3:] * 1e4], -1)  # m, Pa
        same = float(p.loss(t, g, target))
        bare = target.clone()
        bare[..., :3] -= p.contact_base(g) * p.scale
        less = float(p.loss(t, g, bare))
        moved = p.contact_base(g)[0].norm(dim=-1)
        peak = (bare[0, :, :3] / p.scale).norm(dim=-1).max()
        near = g[0] <= features.CONTACT_BAND  # the dent's own term: where the object presses
        share = float(moved.mean() / peak + moved[near].mean() / peak)
    if kind == "gnn":
        assert less == pytest.approx(share, rel=1e-3) and same < 1e-4
    else:  # scored at the chart's corners, where a seam's copies sample the image apart
        assert less > float(moved.mean() / peak) and same < 0.3 * less


def test_a_pose_model_s_reaction_error_is_read_in_its_logarithm(ds):
    """The reaction term of a pose model's loss: the push summed over the vertex areas near the
    object, its error as ``|log(R / R*)|`` (10 % too much push everywhere: log 1.1, whatever the
    pressure's units or the press's weight; 30 % too little where half the reaction is: about
    log 1 / 0.85), pushes far from the object counting for nothing.
    """
    import torch

    p = predictor.create("gnn", ds.part, {**TINY_MODELS["gnn"], "given": "pose"})
    area = torch.tensor(ds.part.vertex_areas, dtype=torch.float32)
    rng = np.random.default_rng(0)
    push = torch.tensor(rng.random((2, ds.part.n_vertices)), dtype=torch.float32)
    push[1] *= 50.0  # a heavier press
    tgt = torch.stack([push, push], -1)  # pressure, push
    gap = torch.zeros(push.shape)  # every vertex touching
    assert float(p.reaction_loss(1.1 * tgt, tgt, gap)) == pytest.approx(np.log(1.1), rel=1e-4)
    far = gap + 0.01  # a push answered 10 mm from the object counts for nothing
    assert float(p.reaction_loss(1.1 * tgt, tgt, far)) > 20.0
    half = torch.cumsum(push * area, -1) <= 0.5 * (push * area).sum(-1, keepdim=True)
    less = tgt.clone()
    less[..., 1] = torch.where(half, 0.7 * push, push)
    share = ((push * area * half).sum(-1) / (push * area).sum(-1)).numpy()
    expected = float(np.mean(-np.log(1 - 0.3 * share)))
    assert float(p.reaction_loss(less, tgt, gap)) == pytest.approx(expected, rel=1e-4)
    assert expected == pytest.approx(-np.log(0.85), abs=0.01)


def test_a_grip_model_s_reaction_is_its_contact_forces_summed(ds):
    """Option ``reaction: pressure`` (a grip's squeeze): the answer's reaction is the sum of its
    contact forces, and the reaction's loss reads the pressure channel, not the push; a model
    given a force is refused the option by name.
    """
    import torch

    from stmpl import tissue
    from stmpl.contact import objects
    from stmpl.contact.posing import posed

    torch.manual_seed(0)
    options = {**TINY_MODELS["gnn"], "given": "pose", "reaction": "pressure"}
    p = predictor.create("gnn", ds.part, options)
    ball = objects.sphere(0.008)
    at = int(np.argmax(ds.part.rim_distance))
    scene = posed(
        ds.part,
        tissue.constant(ds.part, 0.0075),
        ball,
        objects.press(ds.part, ball, at, depth=3e-3),
    )
    d = p.predict(scene)
    assert d.force.sum() > 0 and d.reaction == pytest.approx(d.force.sum(), rel=1e-12)
    n = ds.part.n_vertices
    tgt = torch.ones(1, n, 2)
    tgt[..., 1] = 5.0  # a push five times the pressure: the loss must not read it
    gap = torch.zeros(1, n)
    assert float(p.reaction_loss(tgt, tgt, gap)) == pytest.approx(0.0, abs=1e-6)
    assert p.reaction_channel == 0
    pushed = predictor.create("gnn", ds.part, {**TINY_MODELS["gnn"], "given": "pose"})
    assert pushed.reaction_channel == 1
    with pytest.raises(ValueError, match="reaction says where a pose model"):
        predictor.create("gnn", ds.part, {**TINY_MODELS["gnn"], "reaction": "pressure"})
    with pytest.raises(ValueError, match="reaction must be one of"):
        predictor.create("gnn", ds.part, {**options, "reaction": "sum"})


def test_the_dent_s_error_is_its_own_share_of_the_peak():
    """``near_loss``: the relative MEE over the vertices where an object presses alone; a
    sample where none does counts zero.
    """
    import torch

    from models.losses import near_loss

    target = torch.zeros(2, 4, 3)
    target[:, 0, 2] = 2.0  # a 2-unit dent at vertex 0
    pred = target.clone()
    pred[:, 1, 2] = 0.5  # 0.5 off at vertex 1, pressed in the first sample only
    pred[:, 3, 2] = 1.0  # 1.0 off at vertex 3, never pressed
    near = torch.tensor([[True, True, False, False], [False, False, False, False]])
    assert float(near_loss(pred, target, near)) == pytest.approx(0.5 * (0.25 / 2.0), rel=1e-4)


def test_the_pressures_error_is_read_in_their_logarithm():
    """``log_near_loss``: twice or half a pressure cost alike (log 2), wherever the pressure is
    large against the floor; vertices away from the object and samples with none count zero.
    """
    import torch

    from models.losses import PRESSURE_EPS, log_near_loss

    target = torch.zeros(2, 3, 2)
    target[0, 0] = torch.tensor([10.0, 5.0])
    pred = target.clone()
    pred[0, 0] = torch.tensor([20.0, 2.5])  # twice the pressure, half its push
    pred[0, 2] = 7.0  # far from the object: not scored
    near = torch.tensor([[True, True, False], [False, False, False]])
    e = PRESSURE_EPS
    per_vertex = (np.log((20 + e) / (10 + e)) + np.log((5 + e) / (2.5 + e))) / 2  # both near log 2
    expected = per_vertex / 2 / 2  # over the two near vertices, over the two samples
    assert float(log_near_loss(pred, target, near)) == pytest.approx(expected, rel=1e-3)


@pytest.mark.filterwarnings("ignore::stmpl.failures.ImpossibleAnswer")  # a random network's
@pytest.mark.parametrize("kind", ["gnn", "uv_unet"])
def test_a_pose_model_with_motion_reads_the_way_the_objects_move(ds, tmp_path, kind):
    """Option ``motion``: the model reads the pose's way field beside its gap (a network's
    answer changes with it, a plain pose model's does not), the option travels in the
    checkpoint, a pose without its way is refused by name, and motion needs a pose.
    """
    import torch

    from stmpl import tissue
    from stmpl.contact import objects
    from stmpl.contact.posing import posed

    ball = objects.sphere(0.008)
    at = int(np.argmax(ds.part.rim_distance))
    t = tissue.constant(ds.part, 0.0075)
    scene = posed(ds.part, t, ball, objects.press(ds.part, ball, at, depth=3e-3))
    way = scene.pose.way.copy()
    way[scene.pose.gap < 0.01] = [0.0, 0.8, -0.6]  # a finger sweeping along the skin
    swept = Scene.posed(
        ds.part, t, Pose(scene.pose.gap, scene.pose.direction, scene.pose.objects, way)
    )
    answers = {}
    for motion in (False, True):
        torch.manual_seed(0)
        p = predictor.create(
            kind, ds.part, {**TINY_MODELS[kind], "given": "pose", "motion": motion}
        )
        with torch.no_grad():  # past the silent start: an answer that reads its inputs
            for q in p.model.parameters():
                q.add_(0.1 * torch.randn_like(q))
        answers[motion] = [p.predict(s).displacement for s in (scene, swept)]
    np.testing.assert_array_equal(*answers[False])
    assert np.abs(answers[True][0] - answers[True][1]).max() > 1e-7
    q = predictor.read(p.save(tmp_path / "m.safetensors"))
    assert q.motion
    np.testing.assert_allclose(q.predict(swept).displacement, answers[True][1], atol=1e-9)
    bare = Scene.posed(ds.part, t, Pose(scene.pose.gap, scene.pose.direction, scene.pose.objects))
    with pytest.raises(ValueError, match="reads the way the objects move \\(option motion\\)"):
        q.predict(bare)
    for options, message in [
        ({"motion": True}, "a model given a force has none"),
        ({"given": "pose", "motion": "yes"}, "motion must be true or false"),
    ]:
        with pytest.raises(ValueError, match=message):
            predictor.create(kind, ds.part, {**TINY_MODELS[kind], **options})


def test_a_pose_model_s_displacement_weighs_as_its_option_says(ds):
    """``displacement_weight``: a pose model's loss is the pressures' terms plus that weight
    times the displacement's (two models of the same weights differ by exactly that); a force
    model, and a weight that is not a positive number, are refused by name.
    """
    import torch

    rng = np.random.default_rng(0)
    n = ds.part.n_vertices
    t = torch.full((2, n), 0.0075)
    gap = torch.tensor(rng.uniform(-0.002, 0.02, (2, n)), dtype=torch.float32)
    target = torch.tensor(rng.normal(0, 1e-3, (2, n, 5)), dtype=torch.float32).abs()
    losses = {}
    for w in (1.0, 2.0, 5.0):
        torch.manual_seed(0)
        options = {**TINY_MODELS["gnn"], "given": "pose", "loss": "relative"}
        p = predictor.create("gnn", ds.part, {**options, "displacement_weight": w})
        losses[w] = float(p.loss(t, gap, target))
    shape = losses[2.0] - losses[1.0]
    assert shape > 0 and losses[5.0] - losses[1.0] == pytest.approx(4 * shape, rel=1e-4)
    for options, message in [
        ({"displacement_weight": 2.0}, "a model given a force answers no pressures"),
        ({"given": "pose", "displacement_weight": 0.0}, "displacement_weight"),
        ({"given": "pose", "displacement_weight": "ten"}, "displacement_weight"),
    ]:
        with pytest.raises(ValueError, match=message):
            predictor.create("gnn", ds.part, {**TINY_MODELS["gnn"], **options})
