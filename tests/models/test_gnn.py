"""The mesh GNN: its feature normalisers travel in the checkpoint."""

import numpy as np
import pytest

from models import features
from stmpl import predictor


def test_gnn_normalisers_travel_in_the_checkpoint(ds, tmp_path, make):
    from stmpl import tissue

    p = make("gnn/per_newton", ds)
    q = predictor.read(p.save(tmp_path / "g.safetensors"))
    lo, hi = tissue.THICKNESS_RANGE
    np.testing.assert_allclose(q.model.node_norm.shift.numpy(), [0, 0, lo, 0, 0, 0], atol=1e-9)
    np.testing.assert_allclose(
        q.model.node_norm.scale.numpy(), [1000, 1, hi - lo, 1, 1, 1], rtol=1e-6
    )
    edge_len = np.linalg.norm(np.diff(ds.part.vertices[ds.part.edges], axis=1)[:, 0], axis=1)
    np.testing.assert_allclose(q.model.edge_norm.scale.numpy(), edge_len.mean(), rtol=1e-5)


def test_auto_fidelity_answers_on_the_subgraph_the_load_needs(ds, make):
    """``fidelity="auto"``: the network runs on the region the load moves (where the prior moves
    the tissue) plus ``steps`` hops, so inside the region it answers exactly as on the whole
    mesh, and outside it the answer is the prior's (the linear FEM).
    """
    import torch

    from stmpl.pipeline.evaluate import scenes_of

    p = make("gnn/prior", ds)
    torch.manual_seed(1)
    torch.nn.init.normal_(p.model.net.decoder[-1].weight, std=0.5)  # a correction that shows
    scenes = [s for s in scenes_of(ds, "test")[0] if s.thickness[0] < 0.006][:4]
    full = p.predict(scenes)
    auto = p.with_fidelity("auto").predict(scenes)
    lin = make("linear", ds).predict(scenes)
    t = np.stack([s.thickness for s in scenes])
    f = np.stack([s.force for s in scenes])
    with torch.no_grad():
        base = p.base(torch.tensor(t, dtype=torch.float32), torch.tensor(f, dtype=torch.float32))
    inner, sub = p.region(t, f, base.numpy())  # where the prior moves the tissue
    wide, _ = p.region(t, f)  # within the FEM's first margin
    assert inner.sum() < wide.sum()
    assert (~inner).any() and (inner & ~(np.stack([s.force for s in scenes]) > 0)).any()
    assert (sub >= inner).all()
    for b, (f, a, l) in enumerate(zip(full, auto, lin)):
        np.testing.assert_allclose(
            a.displacement[inner[b]], f.displacement[inner[b]], rtol=1e-4, atol=1e-9
        )
        np.testing.assert_allclose(
            a.displacement[~inner[b]], l.displacement[~inner[b]], rtol=1e-4, atol=1e-9
        )
        assert not np.allclose(f.displacement, l.displacement, atol=1e-7)  # it does correct
    with pytest.raises(ValueError, match="fidelity must be one of"):
        p.with_fidelity("most")
    with pytest.raises(AttributeError):  # given at construction, not written after it
        p.fidelity = "auto"


def test_auto_fidelity_cuts_the_graph_where_no_input_is_lost(arm):
    """On the arm a disk's subgraph is a small part of the mesh, and the network (here without a
    prior: zero outside the region) still answers exactly as on the whole mesh inside it.
    """
    import warnings

    import torch

    from stmpl import loads, tissue
    from stmpl.predictor import ImpossibleAnswer
    from stmpl.scene import Scene

    warnings.simplefilter("ignore", ImpossibleAnswer)  # an untrained net: any answer will do
    torch.manual_seed(0)
    p = predictor.create("gnn", arm, {"latent": 8, "steps": 2})
    torch.nn.init.normal_(p.model.net.decoder[-1].weight, std=0.5)
    s = Scene.from_load(
        arm, tissue.constant(arm, 0.005), loads.disk(arm, uv=(0.3, 0.5), radius=0.02, total=0.2)
    )
    full = p.predict(s).displacement
    auto = p.with_fidelity("auto").predict(s).displacement
    inner, sub = p.region(s.thickness[None], s.force[None])
    assert sub.sum() < arm.n_vertices / 2 and inner.sum() < sub.sum()
    np.testing.assert_allclose(auto[inner[0]], full[inner[0]], rtol=1e-4, atol=1e-9)
    assert np.all(auto[~inner[0]] == 0) and np.abs(full[~inner[0]]).max() > 0


def test_encoded_edges_are_kept_until_the_weights_change(ds, make):
    """At inference the mesh's encoded edges are computed once; a change to the weights (an
    optimiser step, a loaded checkpoint) makes them computed again, never stale.
    """
    import torch

    from stmpl.pipeline.evaluate import scenes_of

    p = make("gnn/prior", ds)
    s = scenes_of(ds, "test", limit=1)[0][0]
    first = p.predict(s).displacement
    kept = p._edges[0][1]
    assert p.predict(s).displacement == pytest.approx(first) and p._edges[0][1] is kept
    with torch.no_grad():
        p.model.net.edge_encoder[0].weight.mul_(2.0)
        torch.nn.init.normal_(p.model.net.decoder[-1].weight, std=0.5)
    with torch.no_grad():
        fresh = p.model.encode_edges(p.edge_attr)
    p.predict(s)
    assert p._edges[0][1] is not kept and torch.equal(p._edges[0][1], fresh)


def test_the_gnn_needs_no_graph_library_and_writes_nothing_to_the_temp_folder(tmp_path):
    """The network is plain torch: a fresh process that builds and runs a GNN imports no graph
    library (whose import pulls in torch._dynamo) and leaves no generated file behind.
    """
    import os
    import subprocess
    import sys

    code = (
        "import sys, torch\n"
        "from models.gnn.network import MeshGraphNet\n"
        "net = MeshGraphNet(latent=8, steps=2)\n"
        "ei = torch.tensor([[0, 1, 2], [1, 2, 0]])\n"
        "out = net(torch.zeros(3, 5), net.edge_encoder(torch.zeros(3, 4)), ei)\n"
        "assert out.shape == (3, 3)\n"
        "heavy = ('torch_geometric', 'torch._dynamo')\n"
        "print(sorted(m for m in sys.modules if m.startswith(heavy)))\n"
    )
    env = {**os.environ, "TMPDIR": str(tmp_path)}
    done = subprocess.run(
        [sys.executable, "-c", code], env=env, capture_output=True, text=True, check=True
    )
    assert done.stdout.strip() == "[]"
    assert not list(tmp_path.iterdir())


def test_a_gnn_given_a_pose_answers_the_same_at_fidelity_auto_near_the_object(ds):
    """``given: pose`` at fidelity auto: the network runs on the region near the object (its
    gap within the contact band) and the steps around it, and answers there as on the whole
    mesh; zero away from it.
    """
    import torch

    from stmpl import tissue
    from stmpl.contact import objects
    from stmpl.contact.posing import posed

    torch.manual_seed(0)
    p = predictor.create("gnn", ds.part, {"latent": 16, "steps": 2, "given": "pose"})
    ball = objects.sphere(0.008)
    at = int(np.argmax(ds.part.rim_distance))
    pose = objects.press(ds.part, ball, at, depth=3e-3)
    scene = posed(ds.part, tissue.constant(ds.part, 0.0075), ball, pose)
    d = p.predict(scene)
    auto = p.with_fidelity("auto").predict(scene)
    near = scene.pose.gap <= features.CONTACT_BAND
    np.testing.assert_allclose(auto.displacement[near], d.displacement[near], atol=1e-7)
    assert not auto.displacement[~near].all(axis=1).all()  # zero away from the object
