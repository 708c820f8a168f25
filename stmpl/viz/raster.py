"""A software rasteriser for triangle meshes seen along the camera's depth axis: a depth buffer
for opaque triangles, see-through ones blended over them, colours interpolated across each
triangle from its corners (Gouraud shading). NumPy only, so a picture needs no OpenGL and no
plotting library.

Coordinates are pixels: ``x`` to the right, ``y`` down, the pixel ``(i, j)`` covering
``[i, i + 1) x [j, j + 1)`` and sampled at its centre; depth grows towards the viewer.
"""

from __future__ import annotations

import numpy as np

CHUNK = 1 << 21
"""Pixel samples (triangle, pixel) made at once: bounds the memory of a large triangle set."""


def fragments(xy: np.ndarray, width: int, height: int):
    """The pixel samples that triangles ``xy`` ``(T, 3, 2)`` (pixels) cover, in chunks: yields
    ``(triangle (K,), pixel (K,) as y * width + x, weights (K, 3))``, the weights each sample's
    barycentric coordinates. A sample on an edge shared by two triangles goes to both.

    Row by row (scanlines): on the row of sample height ``y`` each weight is affine in ``x``,
    so the samples inside a triangle are one run, found from where its three weights are 0.
    """
    xy = np.asarray(xy, float)
    a, b, c = xy[:, 0], xy[:, 1], xy[:, 2]
    area2 = _cross(b - a, c - a)  # twice the signed area
    ok = np.abs(area2) > 1e-12
    y0 = np.maximum(np.ceil(xy[..., 1].min(1) - 0.5), 0).astype(np.int64)
    y1 = np.minimum(np.floor(xy[..., 1].max(1) - 0.5), height - 1).astype(np.int64)
    rows = np.where(ok, np.maximum(y1 - y0 + 1, 0), 0)
    tri = np.repeat(np.arange(len(xy)), rows)  # one (triangle, row) pair each
    y = y0[tri] + np.arange(len(tri)) - np.repeat(np.cumsum(rows) - rows, rows) + 0.5
    # the weights of corners a and b on each pair's row: alpha + beta x
    alpha, beta = np.empty((len(tri), 3)), np.empty((len(tri), 3))
    for n, (q, r) in enumerate([(b, c), (c, a)]):
        e, f, g = _cross(q, r), q[:, 1] - r[:, 1], r[:, 0] - q[:, 0]
        alpha[:, n] = (e[tri] + y * g[tri]) / area2[tri]
        beta[:, n] = f[tri] / area2[tri]
    alpha[:, 2] = 1.0 - alpha[:, 0] - alpha[:, 1]
    beta[:, 2] = -beta[:, 0] - beta[:, 1]
    with np.errstate(divide="ignore", invalid="ignore"):
        cut = -alpha / beta  # where each weight is 0
    lo = np.where(beta > 0, cut, -np.inf).max(1)
    hi = np.where(beta < 0, cut, np.inf).min(1)
    flat = np.where(beta == 0, alpha >= -1e-12, True).all(1)  # an edge along the row
    x0 = np.maximum(np.ceil(lo - 0.5 - 1e-9), 0).astype(np.int64)
    x1 = np.minimum(np.floor(hi - 0.5 + 1e-9), width - 1).astype(np.int64)
    runs = np.where(flat, np.maximum(x1 - x0 + 1, 0), 0)
    ends = np.cumsum(runs)
    first = 0
    while first < len(runs):
        base = ends[first - 1] if first else 0
        last = max(int(np.searchsorted(ends, base + CHUNK, side="right")), first + 1)
        pair = np.repeat(np.arange(first, last), runs[first:last])
        if len(pair):
            px = x0[pair] + np.arange(base, base + len(pair)) - (ends[pair] - runs[pair])
            w = alpha[pair] + beta[pair] * (px + 0.5)[:, None]
            py = (y[pair] - 0.5).astype(np.int64)
            yield tri[pair], py * width + px, w
        first = last


class Raster:
    """An RGB image ``(height, width, 3)`` in [0, 1] on a ``background``, with a depth buffer:
    :meth:`opaque` draws triangles nearest first, :meth:`glass` blends see-through ones over
    what is drawn, :meth:`image` gives the picture, box-filtered down by a supersampling factor.
    """

    def __init__(self, width: int, height: int, background=(1.0, 1.0, 1.0)):
        if width < 1 or height < 1:
            raise ValueError(f"a raster needs a positive size, got {width} x {height}")
        self.width, self.height = int(width), int(height)
        self.rgb = np.empty((self.height * self.width, 3))
        self.rgb[:] = background
        self.depth = np.full(self.height * self.width, -np.inf)

    def opaque(self, xy: np.ndarray, z: np.ndarray, rgb: np.ndarray) -> None:
        """Draw triangles ``xy`` ``(T, 3, 2)`` at corner depths ``z`` ``(T, 3)`` with corner
        colours ``rgb`` ``(T, 3, 3)`` (or one per triangle, ``(T, 3)``), hiding what lies behind.
        """
        rgb = _corners(rgb, len(xy))
        for tri, pix, w in fragments(xy, self.width, self.height):
            d = np.einsum("kc,kc->k", w, z[tri])
            np.maximum.at(self.depth, pix, d)
            won = d >= self.depth[pix]
            self.rgb[pix[won]] = np.einsum("kc,kcj->kj", w[won], rgb[tri[won]])

    def glass(self, xy: np.ndarray, z: np.ndarray, rgb: np.ndarray, alpha: float) -> None:
        """Blend see-through triangles (as :meth:`opaque`, each of opacity ``alpha``) over what
        is drawn, where they lie in front of it. Where ``n`` of them overlap, the pixel keeps
        ``(1 - alpha)^n`` of itself and takes the rest from their mean colour: exact for layers
        of one colour, whatever their order.
        """
        if not 0.0 <= alpha <= 1.0:
            raise ValueError(f"opacity must lie in [0, 1], got {alpha}")
        rgb = _corners(rgb, len(xy))
        pix, colour = [np.zeros(0, np.int64)], [np.zeros((0, 3))]
        for tri, at, w in fragments(xy, self.width, self.height):
            front = np.einsum("kc,kc->k", w, z[tri]) > self.depth[at]
            pix.append(at[front])
            colour.append(np.einsum("kc,kcj->kj", w[front], rgb[tri[front]]))
        pix, colour = np.concatenate(pix), np.concatenate(colour)
        layers = np.bincount(pix, minlength=len(self.depth))
        hit = np.flatnonzero(layers)
        n = layers[hit]
        mean = np.stack([np.bincount(pix, colour[:, j])[hit] for j in range(3)], 1) / n[:, None]
        keep = ((1.0 - alpha) ** n)[:, None]
        self.rgb[hit] = self.rgb[hit] * keep + mean * (1.0 - keep)

    def image(self, factor: int = 1) -> np.ndarray:
        """``(height / factor, width / factor, 3)`` uint8: the picture, each output pixel the
        mean of ``factor x factor`` drawn ones (smooth edges from a supersampled raster).
        """
        h, w = self.height // factor, self.width // factor
        px = self.rgb.reshape(self.height, self.width, 3)[: h * factor, : w * factor]
        px = px.reshape(h, factor, w, factor, 3).mean((1, 3))
        return np.round(np.clip(px, 0.0, 1.0) * 255).astype(np.uint8)


def _cross(u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """``(...)`` the z component of the cross product of 2D vectors ``u``, ``v`` ``(..., 2)``."""
    return u[..., 0] * v[..., 1] - u[..., 1] * v[..., 0]


def _corners(rgb: np.ndarray, n: int) -> np.ndarray:
    """``(T, 3, 3)`` corner colours from per-corner ``(T, 3, 3)`` or per-triangle ``(T, 3)``."""
    rgb = np.asarray(rgb, float)
    if rgb.shape == (n, 3):
        return np.repeat(rgb[:, None], 3, axis=1)
    if rgb.shape != (n, 3, 3):
        raise ValueError(f"colours must be (T, 3) or (T, 3, 3) for {n} triangles, got {rgb.shape}")
    return rgb
