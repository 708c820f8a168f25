"""The UV-UNet: its seam gap, and its relative loss read at the UV corners."""

import numpy as np

from stmpl import predictor
from stmpl.evaluate import scenes_of

TINY_MODELS = {"naive": {}, "linear": {}, "uv_unet": {"size": 64, "width": 4, "depth": 3},
               "gnn": {"latent": 16, "steps": 2}}


def test_seam_gap_unet_has_one_the_gnn_none_by_construction(ds, make):
    import torch

    from stmpl.metrics import seam_gap

    a = ds.arrays("train")
    t, f = (torch.tensor(a[k][:1], dtype=torch.float32) for k in ("thickness", "force"))
    unet = make("uv_unet", ds)
    corners = unet.corner_displacement(t, f)[0]
    assert seam_gap(ds.part, corners) > 0           # copies read different pixels
    gnn = make("gnn", ds)
    u = gnn.predict(scenes_of(ds, "train", limit=1)[0][0]).displacement
    assert seam_gap(ds.part, u[ds.part.uv_vertex]) == 0.0   # one node per vertex


def test_unet_relative_loss_reads_the_corners(ds):
    """The UV-UNet's ``loss: relative`` samples its output at every UV corner: an output image
    that holds the target scores near 0, one that holds 1.1 x the target near the closed form
    0.1 * mean |u| / max |u| (corners, so seam vertices count once per copy)."""
    import torch

    # 256 px: the rasterise -> sample round trip of a peaked field is exact only as pixels shrink
    # (at 64 px it flattens this fixture's one-vertex peaks by a few per cent)
    p = predictor.create("uv_unet", ds.part, {**TINY_MODELS["uv_unet"], "size": 256,
                                              "per_newton": True, "loss": "relative"})
    scenes, truth = scenes_of(ds, "test", limit=2)
    t = torch.tensor(np.stack([s.thickness for s in scenes]), dtype=torch.float32)
    f = torch.tensor(np.stack([s.force for s in scenes]), dtype=torch.float32)
    u = torch.tensor(truth, dtype=torch.float32)
    mag = np.linalg.norm(truth[:, ds.part.uv_vertex], axis=-1)
    expected = np.mean(0.1 * mag.mean(-1) / mag.max(-1))
    for factor, want, tol in ((1.0, 0.0, 0.1 * expected), (1.1, expected, 0.1 * expected)):
        image = p.uvmap.rasterise(p.normalised(factor * u, f))
        p.model = lambda x, image=image: image
        assert abs(float(p.loss(t, f, u)) - want) < tol
