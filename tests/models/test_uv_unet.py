"""The UV-UNet: its seam gap, and its relative loss read at the UV corners."""

import numpy as np
import pytest

from stmpl import predictor
from stmpl.pipeline.evaluate import scenes_of

TINY_MODELS = {
    "naive": {},
    "linear": {},
    "uv_unet": {"size": 64, "width": 4, "depth": 3},
    "gnn": {"latent": 16, "steps": 2},
}


def test_seam_gap_unet_has_one_the_gnn_none_by_construction(ds, make):
    import torch

    from stmpl.metrics import seam_gap

    a = ds.arrays("train")
    t, f = (torch.tensor(a[k][:1], dtype=torch.float32) for k in ("thickness", "force"))
    unet = make("uv_unet", ds)
    corners = unet.corner_displacement(t, f)[0]
    assert seam_gap(ds.part, corners) > 0  # copies read different pixels
    gnn = make("gnn", ds)
    u = gnn.predict(scenes_of(ds, "train", limit=1)[0][0]).displacement
    assert seam_gap(ds.part, u[ds.part.uv_vertex]) == 0.0  # one node per vertex


def test_unet_relative_loss_reads_the_corners(ds):
    """The UV-UNet's ``loss: relative`` samples its output at every UV corner: an output image
    that holds the target scores near 0, one that holds 1.1 x the target near the closed form
    0.1 * mean |u| / max |u| (corners, so seam vertices count once per copy).
    """
    import torch

    # 256 px: the rasterise -> sample round trip of a peaked field is exact only as pixels shrink
    # (at 64 px it flattens this fixture's one-vertex peaks by a few per cent)
    p = predictor.create(
        "uv_unet",
        ds.part,
        {**TINY_MODELS["uv_unet"], "size": 256, "per_newton": True, "loss": "relative"},
    )
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


def test_auto_fidelity_runs_on_the_window_the_load_needs(ds, make):
    """``fidelity="auto"`` on the prior: the network runs on a window of the chart around where
    the prior moves the tissue, wide enough for its receptive field, so there it answers as on
    the whole image (to float rounding), and elsewhere the linear FEM's answer stands.
    """
    import torch

    from stmpl import predictor
    from stmpl.reach import moved

    torch.manual_seed(0)
    p = predictor.create(
        "uv_unet",
        ds.part,
        {**TINY_MODELS["uv_unet"], "size": 128, "per_newton": True, "prior": "linear"},
    )
    p.fit(ds, progress=False)
    last = p.model.net.up[-1][-1]
    torch.nn.init.normal_(last.weight, std=0.5)  # a correction that shows
    scenes = [s for s in scenes_of(ds, "test")[0] if s.thickness[0] < 0.006][:4]
    full = p.predict(scenes)
    auto = p.with_fidelity("auto").predict(scenes)
    lin = predictor.create("linear", ds.part)
    lin.fit(ds, progress=False)
    lin = lin.predict(scenes)
    f = np.stack([s.force for s in scenes])
    inner = moved(ds.part, f, np.stack([d.displacement for d in lin]))
    assert (~inner).any()
    y0, y1, x0, x1 = p.uvmap.window(inner[0], p.crop_margin, 8)
    assert (y1 - y0) * (x1 - x0) < 128**2  # a crop, not the chart
    for b, (u, a, l) in enumerate(zip(full, auto, lin)):
        np.testing.assert_allclose(
            a.displacement[inner[b]], u.displacement[inner[b]], rtol=1e-4, atol=1e-9
        )
        np.testing.assert_allclose(
            a.displacement[~inner[b]], l.displacement[~inner[b]], rtol=1e-4, atol=1e-9
        )
        assert not np.allclose(u.displacement, l.displacement, atol=1e-7)  # it does correct


def test_the_unet_bounds_only_its_bounded_channels():
    """The paper's tanh output on the displacement's channels, none on a pose model's
    log-pressures (``unbounded``): an input scaled up drives those past 1, the others never.
    """
    import torch

    from models.uv_unet.network import UNet

    torch.manual_seed(0)
    net = UNet(2, 5, width=4, depth=2, dropout=0.0, unbounded=2).eval()
    with torch.no_grad():
        y = net(1e3 * torch.randn(1, 2, 16, 16))
    assert y[:, :3].abs().max() <= 1.0 and y[:, 3:].abs().max() > 10.0
    with pytest.raises(ValueError, match="unbounded must be 0..5 output channels, got 6"):
        UNet(2, 5, unbounded=6)
