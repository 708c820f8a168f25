import json
from types import SimpleNamespace

import numpy as np
import pytest

from fem.layers import bound
from models import features
from stmpl import checkpoint, predictor
from stmpl.contact import gap as along
from stmpl.data.dataset import Dataset
from stmpl.failures import OutsideEnvelope
from stmpl.pipeline.evaluate import evaluate, scenes_of
from stmpl.pipeline.train import read_config, train


def _cfg(data, out, **kw):
    return {
        "name": "naive_tiny",
        "model": "naive",
        "data": str(data),
        "epochs": 30,
        "batch": 16,
        "lr": 0.02,
        "patience": 30,
        "out": str(out),
        **kw,
    }


def test_naive_trains_checkpoints_and_reloads(tiny_dataset, tmp_path):
    path = train(_cfg(tiny_dataset, tmp_path / "run"), progress=False)
    meta = checkpoint.read_sidecar(path)
    ds = Dataset(tiny_dataset)
    assert meta["kind"] == "naive" and meta["dataset"]["hash"] == ds.card["hash"]
    assert meta["metrics"]["test"]["mee"][0] > 0
    p = predictor.read(path)
    scenes, truth = scenes_of(ds, "test", limit=5)
    d = p.predict(scenes)
    # alpha was learned: the prediction correlates with the truth better than zero does
    err = np.mean([np.linalg.norm(x.displacement - u) for x, u in zip(d, truth)])
    zero = np.mean([np.linalg.norm(u) for u in truth])
    assert err < zero
    # the same weights give the same answer after a reload
    q = predictor.read(path)
    np.testing.assert_array_equal(q.predict(scenes[0]).displacement, d[0].displacement)
    md = evaluate({"naive_tiny": q}, tiny_dataset, "test", out=tmp_path / "eval")
    assert "naive_tiny" in md and (tmp_path / "eval.csv").exists()


def test_training_resumes_where_it_stopped(tiny_dataset, tmp_path):
    a = train(_cfg(tiny_dataset, tmp_path / "a", epochs=6), progress=False)
    train(_cfg(tiny_dataset, tmp_path / "b", epochs=3), progress=False)
    (tmp_path / "b" / "state.pt.x1y2.tmp").write_bytes(b"")  # a run killed as it wrote
    b = train(_cfg(tiny_dataset, tmp_path / "b", epochs=6), progress=False)  # extends the run
    assert not list((tmp_path / "b").glob("*.tmp"))
    ha = json.loads((tmp_path / "a" / "history.json").read_text())
    hb = json.loads((tmp_path / "b" / "history.json").read_text())
    assert len(ha) == len(hb) == 6
    np.testing.assert_allclose([h["val"] for h in ha], [h["val"] for h in hb], rtol=1e-6)
    assert a.name == b.name
    # training time adds up across the two runs: per-epoch seconds rise, the sidecar's is the sum
    secs = [h["seconds"] for h in hb]
    assert all(s2 >= s1 for s1, s2 in zip(secs, secs[1:])) and secs[2] > 0
    assert json.loads(b.with_suffix(".json").read_text())["training"]["seconds"] == secs[-1]
    with pytest.raises(ValueError, match="another config"):
        train(_cfg(tiny_dataset, tmp_path / "b", lr=0.01), progress=False)


def test_an_edited_sidecar_is_refused(tiny_dataset, tmp_path):
    """The sidecar holds what the predictor reads (its config, the displacement scale): an edit
    there changes every prediction, so it is refused like an edited tensor file.
    """
    path = train(_cfg(tiny_dataset, tmp_path / "run", epochs=2), progress=False)
    side = path.with_suffix(".json")
    meta = json.loads(side.read_text())
    meta["config"]["disp_scale_mm"] = 20.0
    side.write_text(json.dumps(meta, indent=1))
    with pytest.raises(ValueError, match="sidecar .* was edited"):
        predictor.read(path)
    meta["digest"] = checkpoint.digest(meta)  # a consistent forgery passes the file alone...
    side.write_text(json.dumps(meta))
    assert predictor.read(path).scale == pytest.approx(0.02)


def test_a_truncated_training_state_is_named(tiny_dataset, tmp_path, capsys):
    from stmpl.cli.main import main

    train(_cfg(tiny_dataset, tmp_path / "run", epochs=2), progress=False)
    state = tmp_path / "run" / "state.pt"
    state.write_bytes(state.read_bytes()[:100])
    with pytest.raises(ValueError, match="state.pt is truncated or corrupt"):
        train(_cfg(tiny_dataset, tmp_path / "run", epochs=3), progress=False)
    cfg = tmp_path / "c.yaml"
    cfg.write_text(json.dumps(_cfg(tiny_dataset, tmp_path / "run", epochs=3)))
    assert main(["train", str(cfg), "--quiet"]) == 2
    err = capsys.readouterr().err
    assert "state.pt is truncated or corrupt" in err and "Traceback" not in err


def test_training_config_is_checked(tiny_dataset):
    with pytest.raises(ValueError, match="unknown training config keys"):
        read_config({"model": "naive", "data": "x", "epoch": 3})
    with pytest.raises(ValueError, match="model must be a learned predictor"):
        read_config({"model": "fem", "data": "x"})
    with pytest.raises(ValueError, match="lr"):
        read_config({"model": "naive", "data": "x", "lr": -1})
    with pytest.raises(ValueError, match="schedule"):
        read_config({"model": "naive", "data": "x", "schedule": "step"})
    with pytest.raises(ValueError, match="train_fraction"):
        read_config({"model": "naive", "data": "x", "train_fraction": 0})


def test_cosine_schedule_and_placement_share(tiny_dataset):
    import torch

    from stmpl.pipeline.train import _split_tensors, learning_rate

    cfg = read_config({"model": "naive", "data": "x", "lr": 0.1, "schedule": "cosine"})
    assert learning_rate(cfg, 0, 100) == pytest.approx(0.1)
    assert learning_rate(cfg, 50, 100) == pytest.approx(0.05)
    assert learning_rate(cfg, 100, 100) == pytest.approx(0.0, abs=1e-12)
    ds = Dataset(tiny_dataset)
    a = ds.arrays("train")
    places = np.unique(a["placement"])
    half = read_config({"model": "naive", "data": "x", "train_fraction": 0.5})
    t, f, u, body, base = _split_tensors(ds, "train", half, torch.device("cpu"))
    assert body is None and base is None  # one body, no prior
    # whole placements are kept, with all their samples, and about half of them
    kept = {
        int(p)
        for p in places
        if any(
            np.allclose(f[i].numpy(), a["force"][j])
            for i in range(len(f))
            for j in np.flatnonzero(a["placement"] == p)[:1]
        )
    }
    n_kept = sum(int((a["placement"] == p).sum()) for p in kept)
    assert len(kept) == round(0.5 * len(places)) and n_kept == len(f)


def test_linear_fem_is_fitted_not_trained(tiny_dataset, tmp_path, monkeypatch):
    """``model: linear`` computes its operator from the dataset and skips the optimiser; the
    checkpoint says so and beats Naive on the test split; a second fit reads the cache.
    """
    cfg = _cfg(tiny_dataset, tmp_path / "lin", name="lin_tiny", model="linear")
    path = train(cfg, progress=False)
    meta = checkpoint.read_sidecar(path)
    assert meta["kind"] == "linear" and meta["training"]["epochs"] == 0
    assert meta["parameters"] == 0 and meta["operator"]["levels_mm"] == [5.0, 10.0]
    assert 0 < meta["operator"]["dropped"] <= 1e-3 and meta["operator"]["compute_seconds"] > 0
    naive = checkpoint.read_sidecar(train(_cfg(tiny_dataset, tmp_path / "nv"), progress=False))
    assert meta["metrics"]["test"]["mee"][0] < 0.5 * naive["metrics"]["test"]["mee"][0]
    import fem.compliance

    def no_fem(*a, **k):
        raise AssertionError("the cached operator was recomputed")

    monkeypatch.setattr(fem.compliance, "compliance", no_fem)
    again = train({**cfg, "out": str(tmp_path / "lin2")}, progress=False)
    redo = checkpoint.read_sidecar(again)["metrics"]["test"]
    assert redo["mee"] == meta["metrics"]["test"]["mee"]


def test_an_edited_dataset_is_refused_before_training(tiny_dataset, tmp_path):
    """Training checks the shards against the card: an edited sample stops it, by name."""
    import shutil

    import h5py

    data = tmp_path / "data"
    shutil.copytree(tiny_dataset, data)
    shard = sorted(data.glob("shard-*.h5"))[1]
    with h5py.File(shard, "r+") as h:
        h["force"][0, :] = 0.0
    with pytest.raises(ValueError, match=f"{shard.name} was changed after it was written"):
        train(_cfg(data, tmp_path / "run", epochs=1), progress=False)


def test_a_thickness_subset_trains_and_evaluates_on_those_levels_only(tiny_dataset, tmp_path):
    """The paper's "only 3 beta_2" set-up: thickness levels stored as float32 match the
    config's millimetres (they once never did, and the subset was empty).
    """
    ds = Dataset(tiny_dataset)
    a = ds.arrays("train")
    at5 = int(np.sum(np.isclose(a["thickness"][:, 0], 0.005)))
    assert 0 < at5 < len(a["total"])
    p = predictor.read(
        train(_cfg(tiny_dataset, tmp_path / "r", epochs=2, thickness_mm=[5.0]), progress=False)
    )
    assert p.envelope.info["training"]["scenes"] == at5
    assert p.envelope.boxes["training"]["thickness"] == pytest.approx([0.005, 0.005])
    scenes, _ = scenes_of(ds, "test", thickness_mm=[10.0])
    assert scenes and all(np.allclose(s.thickness, 0.010) for s in scenes)
    with pytest.raises(ValueError, match=r"has no training samples at thickness_mm \[6.0\]$"):
        train(_cfg(tiny_dataset, tmp_path / "none", epochs=2, thickness_mm=[6.0]), progress=False)


def test_a_model_trains_on_two_datasets_at_once(tiny_dataset, tmp_path, tiny_config):
    """``data`` may list folders: the envelope and the checkpoint's dataset card cover both."""
    from fem.generate import generate

    generate(
        tiny_config(name="few", thickness_mm=[7.5], forces=[0.05, 0.1, 0.3]),
        tmp_path / "few",
        progress=False,
    )
    data = [str(tiny_dataset), str(tmp_path / "few")]
    path = train({**_cfg(None, tmp_path / "run", epochs=3), "data": data}, progress=False)
    meta = checkpoint.read_sidecar(path)
    assert meta["dataset"]["folder"] == data and meta["dataset"]["name"] == "tiny+few"
    assert [d["name"] for d in meta["dataset"]["datasets"]] == ["tiny", "few"]
    p = predictor.read(path)
    assert p.envelope.boxes["training"]["contact_force"][1] == pytest.approx(0.3, rel=1e-3)
    with pytest.raises(ValueError, match="listed twice"):
        read_config({**_cfg(None, tmp_path / "x"), "data": [data[0], data[0]]})
    with pytest.raises(ValueError, match="list of folders"):
        read_config({**_cfg(None, tmp_path / "x"), "data": [data[0], 3]})


@pytest.mark.parametrize(
    "kind, options",
    [("gnn", {"latent": 16, "steps": 2}), ("uv_unet", {"size": 64, "width": 4, "depth": 3})],
)
def test_a_model_given_the_pose_learns_the_dent_and_the_force_of_pressed_objects(
    tiny_presses, tiny_dataset, tmp_path, kind, options
):
    """A GNN or a UV-UNet given the object's pose (the gap field) trains on pressed objects (its
    loss falls) and answers each test scene with the dent, the contact force on each vertex and the
    reaction, scored against the FEM's (a plumbing test: three samples teach a network little);
    the gap a user's posed ball mesh gives is the dataset's own within the mesh's facets; a
    force-given scene, and a set without poses to train on, are refused by name.
    """
    from stmpl.contact import objects
    from stmpl.contact.posing import posed
    from stmpl.pipeline.evaluate import evaluate_dataset

    cfg = _cfg(
        tiny_presses,
        tmp_path / "run",
        name=f"{kind}_pose",
        model=kind,
        options={**options, "given": "pose"},
        epochs=60,
        batch=4,
        lr=0.01,
    )
    path = train(cfg, progress=False)
    history = json.loads((tmp_path / "run" / "history.json").read_text())
    assert history[-1]["train"] < 0.5 * history[0]["train"]  # it learns
    p = predictor.read(path)
    assert p.takes == ("pose",)
    assert p.tissue == "forearm" and p.bound == bound("forearm")  # judged by its data's tissue
    p.tissue = "my_layers"  # a file of layers the card names: no muscle depth to count
    assert p.bound.compression == np.inf
    ds = Dataset(tiny_presses)
    scenes, truth = scenes_of(ds, "test", given="pose")
    for s, d in zip(scenes, p.predict(scenes)):
        assert d.force.shape == (ds.part.n_vertices,) and d.force.min() >= 0
        assert d.reaction >= 0 and np.isfinite(d.displacement).all()
        reach = features.CONTACT_BAND + features.CONTACT_TAPER
        assert not d.force[s.pose.gap >= reach].any()  # none past the band and its taper
    got = evaluate_dataset(p, ds, "test")
    assert got["samples"] == len(scenes) and np.isfinite(got["reaction_err"][0])
    a = ds.arrays()
    k = list(a["kind"]).index("press_sphere")
    centre, direction = np.array(a["params"][k]["centre"]), np.array(a["params"][k]["direction"])
    ball = objects.sphere(0.008, subdivisions=4)
    pose = np.eye(4)
    pose[:3, 3] = centre - [0, 0, 0.008]  # the mesh's centre on the ball's
    user = posed(ds.part, a["thickness"][k].astype(float), ball, pose, direction=direction)
    sample = along.of_sample(ds.part.vertices, "press_sphere", a["params"][k], a["gap"][k])
    near = sample < 0.01  # the vertices under the ball, along its press
    assert near.sum() >= 1
    np.testing.assert_allclose(user.pose.gap[near], sample[near], atol=5e-5)
    deepest = p.meta["pose_deepest_mm"]
    b = ds.arrays("train")
    reach = [
        along.of_sample(ds.part.vertices, *x).min() for x in zip(b["kind"], b["params"], b["gap"])
    ]
    assert deepest == pytest.approx(-1e3 * min(reach), rel=1e-5)
    pose[:3, 3] += (deepest + 1.0) * 1e-3 * direction  # a millimetre past the deepest
    deeper = posed(ds.part, a["thickness"][k].astype(float), ball, pose, direction=direction)
    with pytest.warns(OutsideEnvelope, match="deeper than any pose in the data"):
        p.predict(deeper)
    with pytest.raises(ValueError, match=f"{kind} answers an object's pose, and scene 0 gives a"):
        p.predict(scenes_of(ds, "test")[0][:1])
    with pytest.raises(ValueError, match="no gap, pressure and push arrays"):
        train({**cfg, "data": str(tiny_dataset), "out": str(tmp_path / "r2")}, progress=False)


@pytest.mark.filterwarnings("ignore::stmpl.failures.OutsideEnvelope")  # five epochs' answers
def test_a_pose_model_with_motion_trains_and_is_measured_on_the_way_its_samples_move(
    tiny_presses, tmp_path
):
    """``motion: true``: training reads each sample's way field beside its gap (a press's:
    its direction near the object), the validation scenes that back its envelope and the
    test scenes it is measured on carry theirs, and the scores equal those of the same
    scenes answered one by one; the NumPy engine reads the way too.
    """
    from stmpl.metrics import sample_metrics
    from stmpl.pipeline.evaluate import evaluate_dataset

    cfg = _cfg(
        tiny_presses,
        tmp_path / "run",
        name="gnn_motion",
        model="gnn",
        options={"latent": 16, "steps": 2, "given": "pose", "motion": True},
        epochs=5,
        batch=4,
        lr=0.01,
    )
    p = predictor.read(train(cfg, progress=False))
    assert p.motion and p.takes == ("pose",)
    ds = Dataset(tiny_presses)
    scenes, truth = scenes_of(ds, "test", given="pose", way=True)
    a = ds.arrays("test")
    for s, params in zip(scenes, a["params"]):
        near = s.pose.gap < 0.01
        np.testing.assert_allclose(s.pose.way[near], np.tile(params["direction"], (near.sum(), 1)))
    got = evaluate_dataset(p, ds, "test")
    rel = [sample_metrics(u, d.displacement)["rel_mee"] for d, u in zip(p.predict(scenes), truth)]
    assert got["samples"] == len(scenes)
    assert got["rel_mee"][0] == pytest.approx(np.mean(rel), rel=1e-4)
    with pytest.raises(ValueError, match="option motion"):
        p.predict(scenes_of(ds, "test", given="pose")[0][:1])
    light = predictor.read(tmp_path / "run" / "gnn_motion.safetensors", engine="numpy")
    for d, e in zip(p.predict(scenes), light.predict(scenes)):  # NumPy reads the way too
        peak = np.abs(d.displacement).max()
        np.testing.assert_allclose(e.displacement, d.displacement, atol=1e-5 * peak)


@pytest.mark.filterwarnings("ignore::stmpl.failures.OutsideEnvelope")  # five epochs' answers
@pytest.mark.filterwarnings("ignore::stmpl.failures.ImpossibleAnswer")  # the tiny set's deep ball
@pytest.mark.parametrize("prior, extra", [("held", {}), ("closure", {"motion": True})])
def test_a_held_pose_model_answers_far_skin_by_the_linear_fem_of_its_data_s_tissue(
    tiny_presses, tmp_path, monkeypatch, prior, extra
):
    """``prior: held`` (and ``closure``, which holds the skin the same way): fitting solves the
    skin's compliance near every sample's object (the checkpoint records it), and every answer
    off the vertices near the object is the tissue's linear FEM's with the answer near it held
    (the FEM wing's float64 holding, within float32 round-off), the same after the checkpoint is
    read again, at ``fidelity="auto"`` and by the NumPy engine; a force model, and a set of the
    paper's gel, are refused by name.
    """
    from fem.holding import Holding
    from models.holding import fit_held

    cfg = _cfg(
        tiny_presses,
        tmp_path / "run",
        name="gnn_held",
        model="gnn",
        options={"latent": 16, "steps": 2, "given": "pose", "prior": prior, "loss": "relative"}
        | extra,
        epochs=5,
        batch=4,
        lr=0.01,
    )
    p = predictor.read(train(cfg, progress=False))
    record = p.meta["holding"]
    assert record["skin"]["tissue"] == "forearm" and record["columns_at_fit"] >= 0
    ds = Dataset(tiny_presses)
    scenes, _ = scenes_of(ds, "test", given="pose", way=bool(extra))
    for s in scenes:  # the fit solved (or found cached) every column a sample of the set holds
        held = p.held_skin.held(s.pose.gap, s.thickness)
        assert p.held_skin.store(s.thickness)[1].missing(held).size == 0
    answers = p.predict(scenes)
    for s, d in zip(scenes, answers):
        held = p.held_skin.held(s.pose.gap, s.thickness)
        assert 0 < len(held) < ds.part.n_vertices
        want = Holding(ds.part, s.thickness, tissue="forearm").answer(held, d.displacement)
        peak = np.abs(want).max()
        assert peak > 0 and np.abs(d.displacement - want).max() < 1e-3 * peak
    again = predictor.read(tmp_path / "run" / "gnn_held.safetensors")
    local = predictor.read(tmp_path / "run" / "gnn_held.safetensors", fidelity="auto")
    import models.gnn.predictor as gnn  # a region of the touched vertices alone, no margin

    monkeypatch.setattr(gnn.reach, "within_margin", lambda part, t, f: f > features.CONTACT_BAND)
    light = predictor.read(tmp_path / "run" / "gnn_held.safetensors", engine="numpy")
    for d, e, f, n in zip(
        answers, again.predict(scenes), local.predict(scenes), light.predict(scenes)
    ):
        np.testing.assert_allclose(e.displacement, d.displacement, atol=1e-9)
        peak = np.abs(d.displacement).max()  # the subgraph answers every held vertex
        np.testing.assert_allclose(f.displacement, d.displacement, atol=1e-5 * peak)
        np.testing.assert_allclose(n.displacement, d.displacement, atol=1e-5 * peak)
    with pytest.raises(ValueError, match="a model given a force takes prior: none or linear"):
        predictor.create("gnn", ds.part, {"prior": prior})
    gel = SimpleNamespace(card={"config": {"tissue": "paper"}})  # a set of the paper's gel
    with pytest.raises(ValueError, match="a layered tissue's linear FEM"):
        fit_held(p, gel)
