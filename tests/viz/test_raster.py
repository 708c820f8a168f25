"""The software rasteriser (stmpl/viz/raster.py): coverage, interpolation, depth, see-through
layers and the supersampled picture, against what they must be exactly.
"""

import numpy as np
import pytest

from stmpl.viz import raster
from stmpl.viz.raster import Raster, fragments

SQUARE = np.array([[[0.0, 0], [10, 0], [10, 10]], [[0.0, 0], [10, 10], [0, 10]]])
"""A 10 x 10 pixel square as two triangles sharing its diagonal."""


def _samples(xy, width=12, height=12):
    parts = list(fragments(xy, width, height))
    return [np.concatenate(p) for p in zip(*parts)]


def test_two_triangles_cover_their_square_exactly_sharing_the_diagonal():
    tri, pix, w = _samples(SQUARE)
    ys, xs = divmod(pix, 12)
    covered = set(zip(xs.tolist(), ys.tolist()))
    assert covered == {(x, y) for x in range(10) for y in range(10)}
    # each triangle: the 45 pixel centres strictly on its side and the 10 on the diagonal
    assert np.bincount(tri).tolist() == [55, 55]
    np.testing.assert_allclose(w.sum(1), 1.0)
    assert (w > -1e-9).all()


def test_weights_are_the_barycentric_coordinates_of_each_pixel_centre():
    xy = np.array([[[1.3, 0.2], [11.7, 4.1], [3.9, 11.2]]])
    _, pix, w = _samples(xy)
    ys, xs = divmod(pix, 12)
    centre = np.stack([xs + 0.5, ys + 0.5], 1)
    np.testing.assert_allclose(w @ xy[0], centre, atol=1e-12)
    # about the triangle's area in samples (the boundary's share at most its perimeter)
    area = 0.5 * abs(np.cross(np.r_[xy[0, 1] - xy[0, 0], 0], np.r_[xy[0, 2] - xy[0, 0], 0])[2])
    assert abs(len(pix) - area) < 0.5 * 30


def test_samples_come_the_same_in_small_chunks(monkeypatch):
    rng = np.random.default_rng(3)
    xy = rng.uniform(-5, 40, (40, 3, 2))
    whole = _samples(xy, 32, 32)
    monkeypatch.setattr(raster, "CHUNK", 7)
    chunked = _samples(xy, 32, 32)
    for a, b in zip(whole, chunked):
        np.testing.assert_array_equal(a, b)
    assert ((whole[1] >= 0) & (whole[1] < 32 * 32)).all()  # clipped to the raster


def test_colours_are_interpolated_linearly_across_a_triangle():
    r = Raster(12, 12)
    xy = SQUARE[:1]
    rgb = np.array([[[1.0, 0, 0], [0, 1, 0], [0, 0, 1]]])
    r.opaque(xy, np.zeros((1, 3)), rgb)
    px = r.rgb.reshape(12, 12, 3)
    # at pixel (7, 2), centre (7.5, 2.5): weights 1 - 0.75, 0.75 - 0.25, 0.25
    np.testing.assert_allclose(px[2, 7], [0.25, 0.5, 0.25])
    np.testing.assert_allclose(px[11, 11], [1.0, 1.0, 1.0])  # outside: the background


def test_the_nearer_triangle_hides_the_farther_in_either_order():
    near = (SQUARE[:1], np.full((1, 3), 2.0), np.array([[1.0, 0, 0]]))
    far = (SQUARE[:1], np.full((1, 3), 1.0), np.array([[0.0, 0, 1]]))
    for order in ((near, far), (far, near)):
        r = Raster(12, 12)
        for xy, z, rgb in order:
            r.opaque(xy, z, rgb)
        np.testing.assert_allclose(r.rgb.reshape(12, 12, 3)[2, 7], [1, 0, 0])


def test_see_through_layers_blend_in_front_and_vanish_behind():
    r = Raster(12, 12, background=(0.0, 0.0, 0.0))
    r.opaque(SQUARE[1:], np.zeros((1, 3)), np.array([[0.0, 0, 0]]))  # the lower left half
    blue = np.array([[0.0, 0.0, 1.0]])
    r.glass(SQUARE[:1], np.full((1, 3), 1.0), blue, 0.3)  # in front of it
    r.glass(SQUARE[:1], np.full((1, 3), 2.0), blue, 0.3)  # twice over
    r.glass(SQUARE[1:], np.full((1, 3), -1.0), blue, 0.3)  # behind the opaque half
    px = r.rgb.reshape(12, 12, 3)
    np.testing.assert_allclose(px[2, 7], [0, 0, 1 - 0.7**2])  # two layers of 0.3
    np.testing.assert_allclose(px[7, 2], [0, 0, 0])  # hidden
    with pytest.raises(ValueError, match="opacity must lie in"):
        r.glass(SQUARE[:1], np.zeros((1, 3)), blue, 1.5)


def test_the_picture_is_the_mean_of_each_block_of_samples():
    r = Raster(4, 2, background=(1.0, 1.0, 1.0))
    r.rgb.reshape(2, 4, 3)[:, :1] = 0.0  # one column of the first 2 x 2 block black
    img = r.image(2)
    assert img.shape == (1, 2, 3) and img.dtype == np.uint8
    assert img[0, 0].tolist() == [128, 128, 128] and img[0, 1].tolist() == [255, 255, 255]


def test_bad_input_is_named():
    with pytest.raises(ValueError, match="positive size"):
        Raster(0, 5)
    with pytest.raises(ValueError, match=r"colours must be \(T, 3\) or \(T, 3, 3\)"):
        Raster(4, 4).opaque(SQUARE, np.zeros((2, 3)), np.zeros((2, 4)))
