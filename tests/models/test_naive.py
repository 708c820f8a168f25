"""The Naive baseline is the paper's formula."""

import numpy as np

from stmpl.pipeline.evaluate import scenes_of


def test_naive_is_the_papers_formula(ds, make):
    import torch

    p = make("naive", ds)
    with torch.no_grad():
        p.model.alpha.copy_(torch.tensor([1.0, -2.0, 0.5]))
    s = scenes_of(ds, "train", limit=1)[0][0]
    u = p.predict(s).displacement
    np.testing.assert_allclose(
        u, (s.thickness * s.force)[:, None] * [1.0, -2.0, 0.5], rtol=1e-5, atol=1e-12
    )
