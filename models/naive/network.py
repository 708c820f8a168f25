"""The Naive baseline's network: ``alpha * t * F`` per axis with a learned ``alpha`` (the
paper's eq. 4); it knows no physics, scenes or envelopes.
"""

from __future__ import annotations

import torch
from torch import nn


class NaiveModel(nn.Module):
    """``(B, N) x (B, N) -> (B, N, 3)``: ``alpha * t * F`` (m), divided by ``scale`` (m)."""

    def __init__(self, scale: float):
        super().__init__()
        self.alpha = nn.Parameter(torch.zeros(3))
        self.scale = scale

    def forward(self, thickness: torch.Tensor, force: torch.Tensor) -> torch.Tensor:
        return (thickness * force)[..., None] * self.alpha / self.scale
