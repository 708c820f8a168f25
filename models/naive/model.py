"""The Naive baseline of the paper (its eq. 4): each vertex moves by ``alpha * t_i * F_i`` with a
learned ``alpha = (alpha_x, alpha_y, alpha_z)`` in global axes (1/N), ``t_i`` the thickness (m) and
``F_i`` the force magnitude (N). It knows nothing of where the load is nor of its direction: the
floor every learned model must clear.
"""

from __future__ import annotations

import torch
from torch import nn

from models.learned import LearnedPredictor


class NaiveModel(nn.Module):
    """``(B, N) x (B, N) -> (B, N, 3)``: ``alpha * t * F`` (m), divided by ``scale`` (m)."""

    def __init__(self, scale: float):
        super().__init__()
        self.alpha = nn.Parameter(torch.zeros(3))
        self.scale = scale

    def forward(self, thickness: torch.Tensor, force: torch.Tensor) -> torch.Tensor:
        return (thickness * force)[..., None] * self.alpha / self.scale


class NaivePredictor(LearnedPredictor):
    """Predictor around :class:`NaiveModel` (no options)."""

    name = "naive"
    defaults: dict = {}
    general = True
    """It knows no geometry, so it answers on every body of its part's mesh alike."""

    def build_model(self) -> nn.Module:
        return NaiveModel(self.scale)

    def raw(self, thickness, force, body=None, base=None):
        return self.model(thickness, force)
