"""The UV-UNet predictor: the network of :mod:`models.uv_unet.network` on the part's UV chart.

Per-vertex inputs become UV images (:mod:`stmpl.uv`): pressure ``F_i / A_i`` over 1 kPa
(resolution-independent, unlike the raw per-vertex force) and thickness normalised over
[2.5, 12.5] mm, optionally geometry (rest positions about the part's centre over its extent,
normals). The output images hold the displacement over ``disp_scale_mm`` (10 mm by default; the
paper's 30 mm); they are sampled back at the vertices, a seam vertex's copies averaged. The loss
is the mean squared error over the chart's pixels and the few padding pixels around it that
bilinear sampling at edge vertices reads (the paper's L2, masked), plus an optional
total-variation term. With ``prior: linear`` the precomputed linear FEM's displacement is three
more channels and the output images hold a correction to it, added at the vertices
(:class:`~models.prior.LinearPrior`).
"""

from __future__ import annotations

import numpy as np
import torch
import torch.nn.functional as F
from torch import nn

from models.features import (
    CONTACT_BAND,
    GAP_SCALE,
    PRESSURE_SCALE,
    PRIOR_SCALE,
    gap_channels,
    gap_of,
    load_channels,
    normalised_thickness,
    way_channels,
)
from models.learned import LearnedPredictor
from models.linear.operator import ComplianceOperator
from models.losses import log_near_loss, near_loss
from models.prior import CORRECTION_SCALE, LinearPrior, start_silent
from models.uv_unet.network import UNet, WithPrior
from stmpl import reach
from stmpl.pose import GAP_REACH
from stmpl.uv import UVMap


class UVUNetPredictor(LinearPrior, LearnedPredictor):
    """UV-UNet predictor. Options: ``size`` (UV image pixels, 64..512), ``width``, ``depth``,
    ``dropout``, ``geometry`` (add position and normal channels), ``tv`` (total-variation weight
    in the loss), ``per_newton`` (inputs: the pressure per newton of the total and the total;
    output: the displacement per newton, ``disp_scale_mm`` then in mm/N), ``loss`` (``mse``,
    ``relative`` or ``pooled``, see :meth:`loss`), ``prior`` (``none``, or ``linear``: the
    precomputed linear FEM's displacement, :mod:`models.linear`, comes in as three more
    channels, the output images hold only the correction, added to the linear answer at the
    vertices, so the prior itself has no seam gap; :meth:`fit` computes the operator). With the
    prior, ``fidelity="auto"`` runs the network on the window of the chart the load needs
    (:meth:`_sample_cropped`). With ``given: pose`` the load's channels are an object's pose
    instead (how deep inside it, over 10 mm, how far outside, over 20 mm) and two more output
    images are the contact pressure and its push along the press (the reaction's density).
    """

    name = "uv_unet"
    defaults = {
        "size": 128,
        "width": 16,
        "depth": 5,
        "dropout": 0.5,
        "geometry": False,
        "tv": 0.0,
        "per_newton": False,
        "loss": "mse",
        "prior": "none",
        "operator": "stored",
    }
    counts = ("size", "width", "depth")
    poses = True

    def network(self) -> nn.Module:
        """The UNet itself (the prior beside it stays eager)."""
        return self.model.net if isinstance(self.model, WithPrior) else self.model

    def build_model(self) -> nn.Module:

        c = self.config
        if not 64 <= int(c["size"]) <= 512 or int(c["size"]) % (2 ** int(c["depth"])):
            raise ValueError(
                f"size must be in [64, 512] and divisible by 2^depth, got "
                f"{c['size']} with depth {c['depth']}"
            )
        self.uvmap = UVMap(self.part, int(c["size"])).to(self.device)
        part = self.part
        self._extent = float(np.ptp(part.vertices, axis=0).max())
        self._geometry = self.geometry_channels(part)
        self._corner_vertex = torch.as_tensor(
            np.asarray(part.uv_vertex), dtype=torch.long, device=self.device
        )
        self._inv_area = torch.tensor(
            1.0 / part.vertex_areas / PRESSURE_SCALE, dtype=torch.float32, device=self.device
        )
        c_in = 2 + (1 if c["per_newton"] or self.posed else 0) + (6 if c["geometry"] else 0)
        c_in += 3 if self.motion else 0  # the way the objects move
        c_in += 3 if c["prior"] == "closure" else 0  # the linear FEM's closure of the objects
        if not self.prior:
            net = UNet(
                c_in,
                self.out_channels,
                int(c["width"]),
                int(c["depth"]),
                float(c["dropout"]),
                unbounded=self.out_channels - 3,  # a pose model's log-pressures
            )
            if self.posed:  # start from the skin laid on the object (or the rest skin)
                start_silent(net.up[-1][-1], posed=True)
            return net
        net = UNet(c_in + 3, 3, int(c["width"]), int(c["depth"]), float(c["dropout"]))
        start_silent(net.up[-1][-1])  # start from the linear FEM: a silent output
        return WithPrior(net, ComplianceOperator())

    def geometry_channels(self, part) -> torch.Tensor:
        """``(N, 6)`` geometry inputs of a body of the mesh: the rest position about the
        part's centre over the model's own part's extent, and the normal.
        """
        geo = np.concatenate(
            [(part.vertices - part.vertices.mean(0)) / self._extent, part.normals], 1
        )
        return torch.tensor(geo, dtype=torch.float32, device=self.device)

    def body_tensors(self, part) -> dict:
        out = super().body_tensors(part)
        out["geometry"] = self.geometry_channels(part)
        return out

    def inputs(self, thickness, force, base=None, body=None) -> torch.Tensor:
        """``(B, N, C)`` per-vertex input channels from ``(B, N)`` thickness (m) and force (N),
        with the prior its answer ``base`` (:meth:`base`, computed once by the caller), on the
        bodies ``body`` ``(B,)`` (slots; None: the model's own).
        """
        inv_area = (
            self._inv_area if body is None else self.body_tensor("inv_area", body) / PRESSURE_SCALE
        )
        if self.posed:  # ``force`` is the gap field (m), and the way the objects move
            inside, outside = gap_channels(gap_of(force))
            load = [inside / GAP_SCALE, outside / GAP_REACH, *way_channels(force)]
        else:
            load = load_channels(force, inv_area, self.per_newton)
        chans = [*load, normalised_thickness(thickness)]
        x = torch.stack(chans, -1)
        if self.config["prior"] == "closure":  # read as well as started from
            x = torch.cat([x, self.closure_base(force, thickness, body) / PRIOR_SCALE], -1)
        if self.config["geometry"]:
            geo = (
                self._geometry.expand(x.shape[0], -1, -1)
                if body is None
                else self.body_tensor("geometry", body)
            )
            x = torch.cat([x, geo], -1)
        if base is not None:
            x = torch.cat([x, base / PRIOR_SCALE], -1)
        return x

    def images(self, thickness, force, base=None, body=None) -> torch.Tensor:
        """``(B, C, S, S)`` input images: :meth:`inputs` on the chart."""
        return self.uvmap.rasterise(self.inputs(thickness, force, base, body))

    def raw(self, thickness, force, body=None, base=None):
        base = self.base(thickness, force, body, base)
        if self.fidelity == "auto" and base is not None and not self.model.training:
            return self.corrected(
                base, self._sample_cropped(self.inputs(thickness, force, base, body), force, base)
            )
        return self.corrected(
            base, self.uvmap.sample(self.model(self.images(thickness, force, base, body)))
        )

    @property
    def crop_margin(self) -> int:
        """Pixels around a window that the network's receptive field reaches in from (4x4
        stride-2 layers, down and up: within 3 * 2^depth pixels), so that inside it a crop's
        output is the whole image's exactly.
        """
        return 3 * 2 ** int(self.config["depth"])

    def _sample_cropped(self, x, force, base):
        """``fidelity="auto"`` on the prior, from the ``(B, N, C)`` :meth:`inputs` ``x``: per
        scene the network runs on a window of the chart (rasterised alone), the pixels that
        sampling reads at :func:`stmpl.reach.moved`'s vertices plus :attr:`crop_margin`,
        aligned to the network's strides; those vertices get its correction (the whole image's,
        exactly), every other vertex none (the prior's answer stands).
        """
        inner = reach.moved(
            self.part,
            force.cpu().numpy(),
            base.detach().cpu().numpy(),
            tolerance=self.region_tolerance,
        )
        m = self.uvmap
        out = x.new_zeros(x.shape[0], x.shape[1], 3)
        for b in np.flatnonzero(inner.any(-1)):
            win = m.window(inner[b], self.crop_margin, 2 ** int(self.config["depth"]))
            v = torch.as_tensor(np.flatnonzero(inner[b]), device=x.device)
            out[b, v] = m.sample(self.model(m.rasterise(x[b : b + 1], win)), win, v)[0]
        return out

    def loss(self, thickness, force, target, body=None, base=None):
        """Masked L2 over the chart's pixels (``loss: mse``, the paper's), or with ``loss:
        relative`` (``pooled``) the relative (pooled) MEE at every UV corner (a seam vertex's
        copies each count), plus the optional total variation.
        """
        base = self.base(thickness, force, body, base)
        out = self.model(self.images(thickness, force, base, body))
        tgt = self.normalised(target, force)
        contact = None
        if self.config["prior"] == "contact":
            contact = F.pad(self.contact_base(gap_of(force), body), (0, tgt.shape[-1] - 3))
        if self.config["loss"] != "mse":
            pred = self.corrected(
                None if base is None else base[:, self._corner_vertex],
                self.with_pressures(self.uvmap.sample_corners(out)),
            )
            if contact is not None:  # the relative error is of the whole answer
                pred = pred + contact[:, self._corner_vertex]
            whole, tgt = tgt, tgt[:, self._corner_vertex]
            loss = self.euclidean_loss(pred[..., :3], tgt[..., :3], force) + self._tv(out)
            if self.posed:  # the dent and the pressures at the corners, the reaction's sum
                vertex = self.with_pressures(self.uvmap.sample(out))[..., 3:]
                gap = gap_of(force)
                near = gap[:, self._corner_vertex] <= CONTACT_BAND
                loss = loss + near_loss(pred[..., :3], tgt[..., :3], near)
                loss = loss + log_near_loss(pred[..., 3:], tgt[..., 3:], near)
                loss = loss + self.reaction_loss(vertex, whole[..., 3:], gap, body)
            return loss
        if contact is not None:  # the image of what the prior leaves
            tgt = tgt - contact
        if base is not None:  # the correction's image
            tgt = (tgt - base) / CORRECTION_SCALE
        tgt = self.uvmap.rasterise(tgt)
        m = self.uvmap.support.to(out.dtype)  # the chart and its padding: sampling reads both
        loss = (((out - tgt) ** 2) * m).sum() / (m.sum() * out.shape[0] * out.shape[1])
        return loss + self._tv(out)

    def _tv(self, out):
        """The total-variation term on the chart's support (0 unless ``tv`` is set)."""
        if not self.config["tv"]:
            return 0.0
        m = self.uvmap.support.to(out.dtype)
        dx = (out[..., :, 1:] - out[..., :, :-1]).abs() * m[:, 1:] * m[:, :-1]
        dy = (out[..., 1:, :] - out[..., :-1, :]).abs() * m[1:] * m[:-1]
        return self.config["tv"] * (dx.mean() + dy.mean())

    def corner_displacement(self, thickness, force, body=None) -> np.ndarray:
        """``(B, T, 3)`` displacement (m) at every UV corner, seam copies apart (``force``: a
        pose model's input, :meth:`given`).
        """
        self.model.eval()
        with torch.no_grad():
            base = self.base(thickness, force, body)
            c = self.uvmap.sample_corners(self.model(self.images(thickness, force, base, body)))
            c = self.corrected(None if base is None else base[:, self._corner_vertex], c)
            if self.config["prior"] == "contact":
                c = (
                    c
                    + F.pad(self.contact_base(gap_of(force), body), (0, c.shape[-1] - 3))[
                        :, self._corner_vertex
                    ]
                )
            return (self.denormalised(c, force)[..., :3] * self.scale).double().cpu().numpy()
