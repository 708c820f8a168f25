"""Per-vertex values <-> UV images of a part's chart.

Rasterising interpolates vertex values barycentrically over the part's UV triangles; pixels just
outside the chart (up to ``pad`` pixels) extend the linear field of their nearest chart pixel's
triangle, so bilinear sampling at a vertex on the chart's edge reads no empty pixel. Sampling reads
each UV corner bilinearly and averages the copies of a seam vertex.

Both directions are fixed sparse maps, precomputed once per part and resolution and applied as
gathers: batched, vectorised, differentiable, and they follow the module to CUDA.

Pixel ``(i, j)`` has its centre at ``u = (j + 0.5) / W``, ``v = 1 - (i + 0.5) / H``, so images
are upright (``v`` grows upwards).
"""

from __future__ import annotations

import weakref

import numpy as np
import torch
from scipy import ndimage

from stmpl.part import BodyPart


class UVMap(torch.nn.Module):
    """The raster plan of one part at one resolution.

    Args:
        part: the body part. size: image side in pixels (``H = W = size``).
        pad: pixels carried past the chart's edge (>= 2 for bilinear sampling at the edge).
    """

    def __init__(self, part: BodyPart, size: int = 256, pad: int = 4) -> None:
        super().__init__()
        if not 8 <= int(size) <= 4096:
            raise ValueError(f"UV image size must be in [8, 4096] pixels, got {size}")
        if pad < 2:
            raise ValueError(f"pad must be >= 2 pixels, got {pad}")
        self.size, self.pad, self.n_vertices = int(size), int(pad), part.n_vertices
        self._corner_of = np.asarray(part.uv_vertex)  # UV corner -> its vertex
        pix, tri, bary, inside = _raster(part.uv, part.face_uv, self.size)
        pix, tri, bary = _dilate(
            pix, tri, bary, inside, self.size, pad, _pixel_xy(part.uv, self.size)[part.face_uv]
        )
        corner_vertex = part.uv_vertex[part.face_uv[tri]]  # (P, 3)
        self.register_buffer("pix", torch.as_tensor(pix, dtype=torch.long))
        self.register_buffer("corner_vertex", torch.as_tensor(corner_vertex, dtype=torch.long))
        self.register_buffer("bary", torch.as_tensor(bary, dtype=torch.float32))
        self.register_buffer("mask", torch.as_tensor(inside.reshape(self.size, self.size)))
        support = np.zeros(self.size * self.size, dtype=bool)
        support[pix] = True
        slot = np.full(self.size * self.size, -1, dtype=np.int64)  # pixel -> its row of pix
        slot[pix] = np.arange(len(pix))
        self.register_buffer("slot", torch.as_tensor(slot.reshape(self.size, self.size)))
        self.register_buffer("support", torch.as_tensor(support.reshape(self.size, self.size)))
        idx, w = _sample_plan(part, self.size)
        self.register_buffer("sample_index", torch.as_tensor(idx, dtype=torch.long))
        self.register_buffer("sample_weight", torch.as_tensor(w, dtype=torch.float32))
        taps, tw = _corner_taps(part.uv, self.size)
        self.register_buffer("corner_index", torch.as_tensor(taps, dtype=torch.long))
        self.register_buffer("corner_weight", torch.as_tensor(tw, dtype=torch.float32))

    def rasterise(
        self, values: torch.Tensor, window: tuple[int, int, int, int] | None = None
    ) -> torch.Tensor:
        """Vertex values ``(N, C)`` or ``(B, N, C)`` -> images ``(C, H, W)`` or ``(B, C, H, W)``;
        with ``window`` ``(y0, y1, x0, x1)`` (:meth:`window`) only those rows and columns,
        ``(B, C, y1 - y0, x1 - x0)``, as cut from the whole image but computed alone.

        Pixels beyond the padded chart are 0; :attr:`mask` marks the chart itself and
        :attr:`support` the chart with its padding (every pixel that sampling can read).
        """
        values, single = self._batch(values, "values", self.n_vertices)
        b, _, c = values.shape
        pix, corner_vertex, w = self.pix, self.corner_vertex, self.bary.to(values.dtype)
        h, wd = self.size, self.size
        if window is not None:
            y0, y1, x0, x1 = window
            h, wd = y1 - y0, x1 - x0
            slot = self.slot[y0:y1, x0:x1].reshape(-1)
            pix = torch.nonzero(slot >= 0).flatten()  # in the window's raster
            sel = slot[pix]
            corner_vertex, w = corner_vertex[sel], w[sel]
        table = values.permute(1, 0, 2).reshape(self.n_vertices, b * c)  # a vertex a row
        px = torch.nn.functional.embedding_bag(  # each pixel's corners, weighted, summed
            corner_vertex, table, per_sample_weights=w, mode="sum"
        )
        px = px.reshape(-1, b, c).transpose(0, 1)  # (B, P, C)
        out = values.new_zeros(b, h * wd, c)
        out = out.index_copy(1, pix, px)
        out = out.transpose(1, 2).reshape(b, c, h, wd)
        return out[0] if single else out

    def sample(
        self,
        images: torch.Tensor,
        window: tuple[int, int, int, int] | None = None,
        vertices: torch.Tensor | None = None,
    ) -> torch.Tensor:
        """Images ``(C, H, W)`` or ``(B, C, H, W)`` -> vertex values ``(N, C)`` or ``(B, N, C)``,
        bilinear at each UV corner, seam copies averaged. With ``window`` the images are that
        window of the chart (:meth:`rasterise`) and ``vertices`` ``(n,)`` the vertices sampled,
        every pixel they read inside it (as :meth:`window` makes it): ``(B, n, C)``.
        """
        single = images.dim() == 3
        images = images[None] if single else images
        if window is None:
            h, wd, idx, w = self.size, self.size, self.sample_index, self.sample_weight
        else:
            y0, y1, x0, x1 = window
            h, wd = y1 - y0, x1 - x0
            taps = self.sample_index[vertices]  # in the whole image
            idx = (taps // self.size - y0).clamp(0, h - 1) * wd + (taps % self.size - x0).clamp(
                0, wd - 1
            )  # unused taps weigh 0
            w = self.sample_weight[vertices]
        if images.dim() != 4 or images.shape[-2:] != (h, wd):
            raise ValueError(
                f"images must be (B, C, {h}, {wd}) or (C, {h}, {wd}), got {tuple(images.shape)}"
            )
        flat = images.flatten(2)  # (B, C, HW)
        out = (flat[:, :, idx] * w.to(images.dtype)).sum(dim=-1).transpose(1, 2)  # (B, N, C)
        return out[0] if single else out

    def sample_corners(self, images: torch.Tensor) -> torch.Tensor:
        """Images ``(B, C, H, W)`` -> values at every UV corner ``(B, T, C)``, seam copies kept
        apart (to measure how far a seam vertex's copies disagree).
        """
        flat = images.flatten(2)
        w = self.corner_weight.to(images.dtype)
        return (flat[:, :, self.corner_index] * w).sum(dim=-1).transpose(1, 2)

    def window(
        self, vertices: np.ndarray, margin: int = 0, align: int = 1
    ) -> tuple[int, int, int, int]:
        """The pixel rows and columns ``(y0, y1, x0, x1)`` (ends exclusive) that bilinear
        sampling reads at every UV corner of the boolean ``(N,)`` ``vertices``, grown by
        ``margin`` pixels on each side, the start and the size multiples of ``align`` (so a
        network with strides up to ``align`` sees the same pixel grid as on the whole image),
        clipped to the image. Raises ``ValueError`` if no vertex is given.
        """
        vertices = np.asarray(vertices, bool)
        if vertices.shape != (self.n_vertices,) or not vertices.any():
            raise ValueError(f"window needs a non-empty ({self.n_vertices},) vertex mask")
        first = self.corner_index[:, 0].cpu().numpy()  # each corner's top-left tap
        y, x = first // self.size, first % self.size
        c = vertices[self._corner_of]
        lo = np.array([y[c].min(), x[c].min()]) - margin
        hi = np.array([y[c].max(), x[c].max()]) + 2 + margin  # taps at x0 and x0 + 1
        lo = np.maximum(lo // align * align, 0)
        hi = np.minimum(-(-hi // align) * align, self.size)
        return int(lo[0]), int(hi[0]), int(lo[1]), int(hi[1])

    @staticmethod
    def _batch(values: torch.Tensor, name: str, n: int) -> tuple[torch.Tensor, bool]:
        values = torch.as_tensor(values)
        single = values.dim() == 2
        values = values[None] if single else values
        if values.dim() != 3 or values.shape[1] != n:
            raise ValueError(
                f"{name} must be (N, C) or (B, N, C) with N = {n}, got {tuple(values.shape)}"
            )
        if not torch.isfinite(values).all():
            raise ValueError(f"{name} contains non-finite values")
        return values, single


def _pixel_xy(uv: np.ndarray, size: int) -> np.ndarray:
    """UV ``(..., 2)`` -> pixel coordinates (x right, y down), pixel centres at integers."""
    return np.stack([uv[..., 0] * size - 0.5, (1.0 - uv[..., 1]) * size - 0.5], -1)


def _barycentric(p: np.ndarray, tri: np.ndarray) -> np.ndarray:
    """Barycentric coordinates ``(P, 3)`` of points ``(P, 2)`` in triangles ``(P, 3, 2)``
    (negative outside: the triangle's linear field extended).
    """
    a, b, c = tri[:, 0], tri[:, 1], tri[:, 2]
    det = (b[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (c[:, 0] - a[:, 0]) * (b[:, 1] - a[:, 1])
    det = np.where(np.abs(det) < 1e-14, 1e-14, det)
    l1 = (p[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (c[:, 0] - a[:, 0]) * (p[:, 1] - a[:, 1])
    l2 = (b[:, 0] - a[:, 0]) * (p[:, 1] - a[:, 1]) - (p[:, 0] - a[:, 0]) * (b[:, 1] - a[:, 1])
    l1, l2 = l1 / det, l2 / det
    return np.stack([1.0 - l1 - l2, l1, l2], 1)


def _raster(uv: np.ndarray, face_uv: np.ndarray, size: int):
    """Pixels whose centres fall in a UV triangle: flat index, triangle, barycentrics."""
    tri_xy = _pixel_xy(uv, size)[face_uv]  # (M, 3, 2)
    lo = np.clip(np.floor(tri_xy.min(1)).astype(int), 0, size - 1)
    hi = np.clip(np.ceil(tri_xy.max(1)).astype(int), 0, size - 1)
    owner = -np.ones(size * size, np.int64)
    bary = np.zeros((size * size, 3))
    for t in range(len(face_uv)):
        gx, gy = np.meshgrid(np.arange(lo[t, 0], hi[t, 0] + 1), np.arange(lo[t, 1], hi[t, 1] + 1))
        p = np.stack([gx.ravel(), gy.ravel()], 1)
        lam = _barycentric(p.astype(float), np.broadcast_to(tri_xy[t], (len(p), 3, 2)))
        ok = (lam >= -1e-9).all(axis=1)
        flat = p[ok, 1] * size + p[ok, 0]
        owner[flat] = t
        bary[flat] = lam[ok]
    inside = owner >= 0
    pix = np.nonzero(inside)[0]
    return pix, owner[pix], bary[pix], inside


def _dilate(pix, tri, bary, inside, size, pad, tri_xy):
    """Extend the plan to pixels within ``pad`` of the chart: each takes the triangle of its
    nearest chart pixel, whose linear field it extends (barycentrics may be negative).
    """
    grid = inside.reshape(size, size)
    dist, (ii, jj) = ndimage.distance_transform_edt(~grid, return_indices=True)
    ring = (~grid) & (dist <= pad)
    src = (ii * size + jj)[ring]
    lookup = -np.ones(size * size, np.int64)
    lookup[pix] = np.arange(len(pix))
    ring_tri = tri[lookup[src]]
    ring_pix = np.nonzero(ring.ravel())[0]
    p = np.stack([ring_pix % size, ring_pix // size], 1).astype(float)
    ring_bary = _barycentric(p, tri_xy[ring_tri])
    return (
        np.concatenate([pix, ring_pix]),
        np.concatenate([tri, ring_tri]),
        np.concatenate([bary, ring_bary]),
    )


def _corner_taps(uv: np.ndarray, size: int) -> tuple[np.ndarray, np.ndarray]:
    """``(T, 4)`` bilinear pixel taps and weights of every UV corner."""
    x, y = _pixel_xy(uv, size).T
    x0 = np.clip(np.floor(x).astype(int), 0, size - 2)
    y0 = np.clip(np.floor(y).astype(int), 0, size - 2)
    fx, fy = np.clip(x - x0, 0, 1), np.clip(y - y0, 0, 1)
    taps = np.stack(
        [y0 * size + x0, y0 * size + x0 + 1, (y0 + 1) * size + x0, (y0 + 1) * size + x0 + 1], 1
    )
    tw = np.stack([(1 - fx) * (1 - fy), fx * (1 - fy), (1 - fx) * fy, fx * fy], 1)
    return taps, tw


def _sample_plan(part: BodyPart, size: int) -> tuple[np.ndarray, np.ndarray]:
    """``(N, 4K)`` pixel indices and weights: bilinear taps of every UV copy, averaged."""
    taps, tw = _corner_taps(part.uv, size)
    copies = np.bincount(part.uv_vertex, minlength=part.n_vertices)
    k = int(copies.max())
    idx = np.zeros((part.n_vertices, 4 * k), np.int64)
    w = np.zeros((part.n_vertices, 4 * k))
    slot = np.zeros(part.n_vertices, np.int64)
    for c in range(len(part.uv)):
        v = part.uv_vertex[c]
        s = slot[v] * 4
        idx[v, s : s + 4] = taps[c]
        w[v, s : s + 4] = tw[c] / copies[v]
        slot[v] += 1
    return idx, w


_CACHE: "weakref.WeakKeyDictionary[BodyPart, dict]" = weakref.WeakKeyDictionary()


def uv_map(part: BodyPart, size: int = 256, pad: int = 4) -> UVMap:
    """A :class:`UVMap` for ``part`` at ``size``, reused while the part object lives."""
    maps = _CACHE.setdefault(part, {})
    key = (int(size), int(pad))
    if key not in maps:
        maps[key] = UVMap(part, size, pad)
    return maps[key]
