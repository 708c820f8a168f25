"""A compiled network answers as the eager one, or is refused and left eager."""

import numpy as np
import pytest
import torch

from models import compiled


def test_compiling_without_a_compiler_says_what_to_install(monkeypatch):
    monkeypatch.delenv("CXX", raising=False)
    monkeypatch.setattr(compiled.shutil, "which", lambda name: None)
    net = torch.nn.Linear(2, 2)
    with pytest.raises(RuntimeError, match="needs a C.. compiler"):
        compiled.compile_module(net)
    assert not compiled.is_compiled(net)


def test_a_compiled_module_trains_eagerly_and_can_be_undone():
    net = torch.nn.Linear(3, 2)
    eager = net.forward
    compiled.compile_module(net)
    assert compiled.is_compiled(net)
    x = torch.randn(4, 3, requires_grad=True)
    net(x).sum().backward()  # with gradients on: the eager forward, nothing compiled
    assert x.grad is not None and x.grad.shape == (4, 3)
    compiled.uncompiled(net)
    assert not compiled.is_compiled(net) and net.forward == eager


def test_a_compiled_answer_that_strays_is_refused_and_left_eager(ds, make, monkeypatch):
    """``compile`` checks the compiled answer against the eager one: a network that answers
    otherwise once compiled (here: a compile that doubles the output) is refused.
    """
    p = make("gnn/prior", ds)

    def doubling(module):
        eager = module.forward
        module._eager = eager
        module.forward = lambda *a, **k: 2 * eager(*a, **k)

    monkeypatch.setattr("models.learned.compile_module", doubling)
    torch.nn.init.normal_(p.model.net.decoder[-1].weight, std=0.5)  # an output that shows
    with pytest.raises(RuntimeError, match="left eager"):
        p.compile()
    assert not compiled.is_compiled(p.model.net)


@pytest.mark.slow
def test_the_compiled_gnn_answers_as_the_eager_one(ds, make):
    """Inductor's kernels on a tiny GNN at both fidelities: within 1e-4 of the deepest
    displacement, and a subgraph of another size does not change that.
    """
    from stmpl.pipeline.evaluate import scenes_of

    p = make("gnn/prior", ds)
    torch.nn.init.normal_(p.model.net.decoder[-1].weight, std=0.5)
    scenes = scenes_of(ds, "test")[0][:3]
    for q in (p, p.with_fidelity("auto")):
        eager = [d.displacement for d in q.predict(scenes)]
        compiled.uncompiled(q.model.net)
        q.compile(scenes[0])
        assert compiled.is_compiled(q.model.net)
        for s, u in zip(scenes, eager):
            deep = np.linalg.norm(u, axis=1).max()
            assert np.abs(q.predict(s).displacement - u).max() <= 1e-4 * deep
