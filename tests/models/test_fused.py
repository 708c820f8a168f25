"""The GNN's fused processor (compiled loops between torch's products) answers as the eager
steps do, on the whole graph, on a subgraph's shrinking steps and on a trained checkpoint, and
never runs where gradients are wanted or on stale weights.
"""

import numpy as np
import pytest
import torch

from models.gnn import fused
from models.gnn.network import MeshGraphNet

pytestmark = pytest.mark.skipif(fused.kernels(load=True) is None, reason="Numba is not installed")


def _graph(V: int = 60, E: int = 400, seed: int = 0):
    g = torch.Generator().manual_seed(seed)
    net = MeshGraphNet(5, 4, 3, latent=16, steps=3).eval()
    for p in net.parameters():  # weights far from their start: every term counts
        torch.nn.init.normal_(p, std=0.4, generator=g)
    x = torch.randn(V, 5, generator=g)
    ei = torch.randint(0, V, (2, E), generator=g)
    with torch.no_grad():
        e = net.edge_encoder(torch.randn(E, 4, generator=g))
    return net, x, e, ei


def _eager(net, *args):
    real = fused.usable
    fused.usable = lambda h: False
    try:
        return net(*args)
    finally:
        fused.usable = real


def test_fused_steps_equal_the_eager_ones_on_the_whole_graph():
    net, x, e, ei = _graph()
    with torch.no_grad():
        want = _eager(net, x, e, ei)
        got = net(x, e, ei)
    assert got.shape == want.shape == (60, 3)
    assert float((got - want).abs().max()) <= 1e-5 * float(want.abs().max())


def test_fused_steps_equal_the_eager_ones_on_shrinking_steps():
    """Step ``s`` updates the first ``n`` nodes over the first ``m`` edges (edges sorted by
    target): the answer on the last step's nodes is the eager one's.
    """
    net, x, _, _ = _graph()
    g = torch.Generator().manual_seed(1)
    bands = [(0, 10, 25), (10, 25, 40), (25, 40, 60)]  # targets [a, b) read sources < c
    ei = torch.cat(
        [
            torch.stack(
                [torch.randint(0, c, (80,), generator=g), torch.randint(a, b, (80,), generator=g)]
            )
            for a, b, c in bands
        ],
        1,
    )
    ei = ei[:, torch.argsort(ei[1], stable=True)]
    with torch.no_grad():
        e = net.edge_encoder(torch.randn(ei.shape[1], 4, generator=g))
    sizes = [(n, int((ei[1] < n).sum())) for n in (40, 25, 10)]
    with torch.no_grad():
        want = _eager(net, x, e, ei, sizes)
        got = net(x, e, ei, sizes)
    assert got.shape == want.shape == (10, 3)
    assert float((got - want).abs().max()) <= 1e-5 * float(want.abs().max())


def test_the_encoded_edges_are_left_as_they_were():
    net, x, e, ei = _graph()
    before = e.clone()
    with torch.no_grad():
        net(x, e, ei)
    assert torch.equal(e, before)


def test_gradients_and_training_take_the_eager_steps():
    net, x, e, ei = _graph()
    out = net(x, e, ei)  # gradients on: eager, differentiable
    assert out.requires_grad
    net.train()
    calls = []
    real = fused.processor
    fused.processor = lambda *a, **k: calls.append(1) or real(*a, **k)
    try:
        with torch.no_grad():
            net(x, e, ei)
        assert not calls
        net.eval()
        with torch.no_grad():
            net(x, e, ei)
        assert calls
    finally:
        fused.processor = real


def test_changed_weights_are_laid_out_again():
    """A step's weights are laid out once; an in-place change (an optimiser step) or a loaded
    state is seen at the next answer, never a stale copy.
    """
    net, x, e, ei = _graph()
    with torch.no_grad():
        first = net(x, e, ei)
        net.processor[1].edge_out[1].weight.mul_(-1.0)
        changed = net(x, e, ei)
        want = _eager(net, x, e, ei)
    assert float((changed - first).abs().max()) > 1e-3
    assert float((changed - want).abs().max()) <= 1e-5 * float(want.abs().max())
    other = MeshGraphNet(5, 4, 3, latent=16, steps=3).eval()
    with torch.no_grad():
        net.load_state_dict(other.state_dict())
        loaded = net(x, e, ei)
        want = _eager(other, x, e, ei)
    assert float((loaded - want).abs().max()) <= 1e-5 * float(want.abs().max())


def test_a_shipped_gnn_answers_as_before_with_the_loops_loaded(arm):
    """The default model at both fidelities, fused against eager: within 1e-6 of the deepest
    displacement (float32 sums in another order).
    """
    import warnings

    from stmpl import loads, tissue
    from stmpl.pipeline import zoo
    from stmpl.scene import Scene

    s = Scene.from_load(
        arm.subdivided(1),
        tissue.constant(arm.subdivided(1), 0.0075),
        loads.disk(arm.subdivided(1), uv=(0.5, 0.5), radius=0.02, total=0.3),
    )
    for fidelity in ("full", "auto"):
        p = zoo.read("gnn_arm_bodies", fidelity=fidelity)
        with warnings.catch_warnings(), torch.no_grad():
            warnings.simplefilter("ignore")
            real = fused.usable
            fused.usable = lambda h: False
            try:
                want = p.predict(s).displacement
            finally:
                fused.usable = real
            got = p.predict(s).displacement
        deepest = float(np.linalg.norm(want, axis=1).max())
        assert float(np.abs(got - want).max()) <= 1e-6 * deepest
