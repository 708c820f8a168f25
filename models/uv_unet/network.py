"""The paper's UV-space UNet (pix2pix-style): images in, images out; it knows no physics, scenes
or envelopes (the predictor, :mod:`models.uv_unet.predictor`, builds its inputs).

:class:`UNet`: ``depth`` down-steps of 4x4 convolutions with stride 2 (LeakyReLU 0.2 before each
but the first, no normalisation), and as many 4x4 transposed convolutions up with skip
connections (LeakyReLU 0.2 before each, dropout 0.5 on the three innermost), a tanh output
(but on the last ``unbounded`` channels). Channels double from ``width`` up to ``8 * width``.
Images ``(B, C_in, S, S) -> (B, C_out, S, S)``.
:class:`WithPrior` keeps a UNet beside a prior module its predictor adds, so one checkpoint
carries both.
"""

from __future__ import annotations

import torch
from torch import nn


class UNet(nn.Module):
    """pix2pix UNet: ``(B, C_in, S, S) -> (B, C_out, S, S)`` in [-1, 1] (the last
    ``unbounded`` channels unbounded: no tanh); ``S`` divisible by ``2 ** depth``.
    """

    def __init__(
        self,
        c_in: int,
        c_out: int = 3,
        width: int = 16,
        depth: int = 5,
        dropout: float = 0.5,
        unbounded: int = 0,
    ):
        super().__init__()
        if not 0 <= unbounded <= c_out:
            raise ValueError(f"unbounded must be 0..{c_out} output channels, got {unbounded}")
        self.unbounded = unbounded
        ch = [width * 2 ** min(d, 3) for d in range(depth)]
        self.down = nn.ModuleList()
        prev = c_in
        for d, c in enumerate(ch):
            layers = [] if d == 0 else [nn.LeakyReLU(0.2)]
            self.down.append(nn.Sequential(*layers, nn.Conv2d(prev, c, 4, 2, 1)))
            prev = c
        self.up = nn.ModuleList()
        for d in reversed(range(depth)):
            c_skip = 0 if d == depth - 1 else ch[d]
            c_out_d = ch[d - 1] if d > 0 else c_out
            layers = [nn.LeakyReLU(0.2), nn.ConvTranspose2d(ch[d] + c_skip, c_out_d, 4, 2, 1)]
            if 0 < d and d >= depth - 3 and dropout > 0:
                layers.append(nn.Dropout(dropout))
            self.up.append(nn.Sequential(*layers))
        self.depth = depth

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        if x.shape[-1] % (2**self.depth) or x.shape[-2] % (2**self.depth):
            raise ValueError(f"image size {tuple(x.shape[-2:])} is not divisible by 2^{self.depth}")
        skips = []
        for layer in self.down:
            x = layer(x)
            skips.append(x)
        x = skips.pop()
        for i, layer in enumerate(self.up):
            if i > 0:
                x = torch.cat([x, skips.pop()], dim=1)
            x = layer(x)
        if not self.unbounded:
            return torch.tanh(x)
        k = x.shape[1] - self.unbounded
        return torch.cat([torch.tanh(x[:, :k]), x[:, k:]], 1)


class WithPrior(nn.Module):
    """A :class:`UNet` and the linear FEM operator its predictor adds (``prior: linear``), kept
    together so the checkpoint carries both; calling it runs the UNet.
    """

    def __init__(self, net: UNet, prior: nn.Module):
        super().__init__()
        self.net, self.prior = net, prior

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return self.net(x)
