"""The losses a learned model trains on, over ``(B, N, 3)`` tensors in the units of its raw
output: the relative MEE (each sample's mean Euclidean error over its peak), the same over the
vertices where an object presses, the pooled one (the batch's errors over its peaks, summed
first), and a pose model's pressures' error in their logarithm where an object presses.
"""

from __future__ import annotations

import torch

LOSS_EPS = 1e-6
"""Regularises the losses' norms (units of :meth:`models.learned.LearnedPredictor.raw`, about
1e-6 of the full scale, well under any error that counts)."""


def _errors(pred, target):
    """``(B, N)`` Euclidean errors (smooth at zero, ``LOSS_EPS``) and ``(B,)`` peaks of the
    targets, for ``(B, N, 3)`` tensors.
    """
    norm = torch.sqrt(((pred - target) ** 2).sum(-1) + LOSS_EPS**2)
    return norm, target.norm(dim=-1).amax(-1)


def _near_mean(x, near):
    """``(B,)`` the mean of ``x`` ``(B, N)`` over the vertices ``near`` ``(B, N)`` (bool); zero
    for a sample with none.
    """
    w = near.to(x.dtype)
    return (x * w).sum(-1) / w.sum(-1).clamp_min(1.0)


def relative_loss(pred, target):
    """Mean over samples of ``mean_i |pred_i - target_i| / max_i |target_i|`` for ``(B, N, 3)``
    tensors: the relative MEE, smooth at zero error (``LOSS_EPS``).
    """
    norm, peak = _errors(pred, target)
    return (norm.mean(-1) / (peak + LOSS_EPS)).mean()


def near_loss(pred, target, near):
    """Mean over samples of the mean Euclidean error over the vertices ``near`` ``(B, N)``
    (bool) over the sample's peak, for ``(B, N, 3)`` tensors: :func:`relative_loss` on where an
    object presses (a sample with none such counts zero).
    """
    norm, peak = _errors(pred, target)
    return (_near_mean(norm, near) / (peak + LOSS_EPS)).mean()


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
    return _near_mean(err, near).mean()


def pooled_loss(pred, target, weight=None):
    """The batch's summed mean Euclidean error over its summed peak displacement for ``(B, N, 3)``
    tensors, each sample weighted by ``weight`` ``(B,)`` (per-newton tensors: the total force, so
    the sums are of absolute displacements): ``sum_b w_b MEE_b / sum_b w_b max_i |target_bi|``.
    Unlike :func:`relative_loss`, a heavy press weighs more than a light one, as it does in the
    mean MEE over a test set (and in its ratio to Naive's).
    """
    norm, peak = _errors(pred, target)
    w = torch.ones_like(peak) if weight is None else weight
    return (w * norm.mean(-1)).sum() / ((w * peak).sum() + LOSS_EPS)
