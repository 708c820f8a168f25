"""The losses a learned model trains on, over ``(B, N, 3)`` tensors in the units of its raw
output: the relative MEE (each sample's mean Euclidean error over its peak), the same over the
vertices where an object presses, and the pooled one (the batch's errors over its peaks, summed
first).
"""

from __future__ import annotations

import torch

LOSS_EPS = 1e-6
"""Regularises the losses' norms (units of :meth:`models.learned.LearnedPredictor.raw`, about
1e-6 of the full scale, well under any error that counts)."""


def relative_loss(pred, target):
    """Mean over samples of ``mean_i |pred_i - target_i| / max_i |target_i|`` for ``(B, N, 3)``
    tensors: the relative MEE, smooth at zero error (``LOSS_EPS``).
    """
    norm = torch.sqrt(((pred - target) ** 2).sum(-1) + LOSS_EPS**2)  # (B, N)
    peak = target.norm(dim=-1).amax(-1)  # (B,)
    return (norm.mean(-1) / (peak + LOSS_EPS)).mean()


def near_loss(pred, target, near):
    """Mean over samples of the mean Euclidean error over the vertices ``near`` ``(B, N)``
    (bool) over the sample's peak, for ``(B, N, 3)`` tensors: :func:`relative_loss` on where an
    object presses (a sample with none such counts zero).
    """
    norm = torch.sqrt(((pred - target) ** 2).sum(-1) + LOSS_EPS**2)  # (B, N)
    peak = target.norm(dim=-1).amax(-1)  # (B,)
    w = near.to(norm.dtype)
    return ((norm * w).sum(-1) / w.sum(-1).clamp_min(1.0) / (peak + LOSS_EPS)).mean()


PRESSURE_EPS = 0.01
"""The smallest pressure :func:`log_near_loss` tells apart from none, in a pose model's pressure
unit (10 kPa: 100 Pa, a hundredth of a light touch's peak)."""


def log_near_loss(pred, target, near):
    """Mean over samples of the mean ``|log(p + eps) - log(t + eps)|`` over the vertices ``near``
    ``(B, N)`` (bool) for ``(B, N, C)`` non-negative tensors (a pose model's pressures, units of
    10 kPa; ``eps`` :data:`PRESSURE_EPS`): each pressure's relative error, as read from the
    logarithm a network answers it in (:func:`models.features.pressure_out`). An absolute error
    over the peak would let an answer of nearly none everywhere cost little (most vertices near
    an object carry none), and its gradient through the exponential fades as the answer does.
    """
    err = (torch.log(pred + PRESSURE_EPS) - torch.log(target + PRESSURE_EPS)).abs().mean(-1)
    w = near.to(err.dtype)
    return ((err * w).sum(-1) / w.sum(-1).clamp_min(1.0)).mean()


def pooled_loss(pred, target, weight=None):
    """The batch's summed mean Euclidean error over its summed peak displacement for ``(B, N, 3)``
    tensors, each sample weighted by ``weight`` ``(B,)`` (per-newton tensors: the total force, so
    the sums are of absolute displacements): ``sum_b w_b MEE_b / sum_b w_b max_i |target_bi|``.
    Unlike :func:`relative_loss`, a heavy press weighs more than a light one, as it does in the
    mean MEE over a test set (and in its ratio to Naive's).
    """
    norm = torch.sqrt(((pred - target) ** 2).sum(-1) + LOSS_EPS**2)  # (B, N)
    peak = target.norm(dim=-1).amax(-1)  # (B,)
    w = torch.ones_like(peak) if weight is None else weight
    return (w * norm.mean(-1)).sum() / ((w * peak).sum() + LOSS_EPS)
