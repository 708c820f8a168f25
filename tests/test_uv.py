import numpy as np
import pytest
import torch

from stmpl.body import tube
from stmpl.uv import UVMap, uv_map


def _smooth_field(part):
    x = part.vertices
    return torch.tensor(
        np.stack(
            [np.sin(20 * x[:, 0]) + np.cos(15 * x[:, 2]), 10 * x[:, 1], x[:, 0] * x[:, 2] * 40], 1
        ),
        dtype=torch.float64,
    )


def test_round_trip_of_a_smooth_field_within_one_percent(arm):
    m = UVMap(arm, 256)
    f = _smooth_field(arm)
    back = m.sample(m.rasterise(f))
    rel = (back - f).abs().max(0).values / (f.max(0).values - f.min(0).values)
    assert rel.max() < 0.01, rel


def test_round_trip_error_falls_with_resolution(arm):
    f = _smooth_field(arm)
    errs = [
        (UVMap(arm, s).sample(UVMap(arm, s).rasterise(f)) - f).abs().mean().item()
        for s in (64, 128, 256)
    ]
    assert errs[0] > errs[1] > errs[2]
    assert errs[0] / errs[2] > 3  # about first order in the pixel size


def test_linear_field_is_reproduced_exactly_inside_triangles():
    p = tube(n_around=16, n_along=6)
    m = UVMap(p, 128)
    f = torch.tensor(p.vertices[:, 2:3] * 3.0)  # linear along the tube, also across the seam
    np.testing.assert_allclose(m.sample(m.rasterise(f)).numpy(), f.numpy(), atol=1e-9)


def test_mask_covers_the_chart_area(arm):
    m = UVMap(arm, 256)
    t = arm.uv[arm.face_uv]
    e1, e2 = t[:, 1] - t[:, 0], t[:, 2] - t[:, 0]
    area = 0.5 * np.abs(e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0]).sum()
    assert m.mask.float().mean().item() == pytest.approx(area, rel=0.02)


def test_seam_copies_are_averaged(arm):
    m = UVMap(arm, 128)
    img = torch.zeros(1, 128, 128)
    g = arm.seam_groups[5]
    c0 = arm.uv[g[0]]
    # paint only the neighbourhood of the first copy: the vertex reads the mean of its copies
    i, j = int((1 - c0[1]) * 128), int(c0[0] * 128)
    img[0, i - 3 : i + 4, j - 3 : j + 4] = 1.0
    v = arm.uv_vertex[g[0]]
    assert m.sample(img)[v, 0].item() == pytest.approx(1.0 / len(g), abs=1e-6)


def test_batched_and_differentiable(arm, rng):
    m = uv_map(arm, 64)
    x = torch.tensor(rng.normal(size=(3, arm.n_vertices, 2)), requires_grad=True)
    imgs = m.rasterise(x)
    assert imgs.shape == (3, 2, 64, 64)
    torch.testing.assert_close(imgs[1], m.rasterise(x[1]))
    out = m.sample(imgs)
    assert out.shape == (3, arm.n_vertices, 2)
    out.sum().backward()
    assert torch.isfinite(x.grad).all() and x.grad.abs().sum() > 0
    assert uv_map(arm, 64) is m


def test_bad_input(arm):
    m = uv_map(arm, 64)
    with pytest.raises(ValueError, match=r"values must be \(N, C\)"):
        m.rasterise(torch.zeros(10, 1))
    with pytest.raises(ValueError, match="non-finite"):
        m.rasterise(torch.full((arm.n_vertices, 1), float("nan")))
    with pytest.raises(ValueError, match="images must be"):
        m.sample(torch.zeros(1, 32, 32))
    with pytest.raises(ValueError, match="size must be in"):
        UVMap(arm, 4)


def test_support_covers_every_pixel_sampling_reads(arm):
    from stmpl.uv import UVMap

    m = UVMap(arm, 64)
    assert m.mask.sum() < m.support.sum()
    assert bool(m.support[m.mask].all())
    read = m.sample_index[m.sample_weight > 0]
    assert bool(m.support.flatten()[read].all())


def test_window_holds_every_pixel_a_vertex_set_samples(arm):
    """``window``: the pixels bilinear sampling reads at a set of vertices, grown by a margin,
    aligned and clipped: an image that is zero outside the window samples those vertices as
    the whole image does; a margin or alignment only grows it; an empty set is refused.
    """
    m = UVMap(arm, 128)
    near = np.linalg.norm(arm.vertices - arm.vertices[0], axis=1) < 0.03
    y0, y1, x0, x1 = m.window(near)
    assert 0 < (y1 - y0) * (x1 - x0) < 0.25 * 128**2  # a small part of the chart
    field = _smooth_field(arm).float()
    image = m.rasterise(field)
    cut = torch.zeros_like(image)
    cut[:, y0:y1, x0:x1] = image[:, y0:y1, x0:x1]
    np.testing.assert_allclose(m.sample(cut)[near].numpy(), m.sample(image)[near].numpy())
    assert not np.allclose(m.sample(cut).numpy(), m.sample(image).numpy())
    a = m.window(near, margin=5, align=8)
    assert a[0] <= y0 - 5 or a[0] == 0
    assert a[3] >= min(x1 + 5, 128) and all(v % 8 == 0 for v in a)
    with pytest.raises(ValueError, match="non-empty"):
        m.window(np.zeros(arm.n_vertices, bool))


def test_a_window_rasterised_alone_is_the_cut_of_the_whole_image(arm):
    m = UVMap(arm, 128)
    field = _smooth_field(arm).float()
    near = np.linalg.norm(arm.vertices - arm.vertices[0], axis=1) < 0.03
    y0, y1, x0, x1 = win = m.window(near, margin=7, align=8)
    whole = m.rasterise(field[None])
    alone = m.rasterise(field[None], win)
    assert alone.shape == (1, 3, y1 - y0, x1 - x0)
    assert torch.equal(alone, whole[:, :, y0:y1, x0:x1])


def test_sampling_a_window_reads_what_the_whole_image_gives(arm):
    m = UVMap(arm, 128)
    field = _smooth_field(arm).float()
    near = np.linalg.norm(arm.vertices - arm.vertices[5], axis=1) < 0.03
    win = m.window(near, margin=3, align=4)
    v = torch.as_tensor(np.flatnonzero(near))
    whole = m.sample(m.rasterise(field[None]))[0, v]
    alone = m.sample(m.rasterise(field[None], win), win, v)[0]
    np.testing.assert_allclose(alone.numpy(), whole.numpy(), rtol=1e-6, atol=1e-6)
    with pytest.raises(ValueError, match="images must be"):
        m.sample(m.rasterise(field[None]), win, v)
