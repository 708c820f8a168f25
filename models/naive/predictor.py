"""The Naive baseline of the paper (its eq. 4): each vertex moves by ``alpha * t_i * F_i`` with a
learned ``alpha = (alpha_x, alpha_y, alpha_z)`` in global axes (1/N), ``t_i`` the thickness (m) and
``F_i`` the force magnitude (N). It knows nothing of where the load is nor of its direction: the
floor every learned model must clear.
"""

from __future__ import annotations

from torch import nn

from models.learned import LearnedPredictor
from models.naive.network import NaiveModel


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
