"""Input features every learned model shares, defined once: the load as pressure (or, per
newton, its pattern and the total force), the thickness normalised over the tissue range, and
the scale of the linear prior's displacement as an input. Torch tensors, SI units in.
"""

from __future__ import annotations

from stmpl import tissue

PRESSURE_SCALE = 1000.0
"""Pa: pressure inputs are divided by this (the tissue's Young's modulus in the paper)."""

THICKNESS_SHIFT = tissue.THICKNESS_RANGE[0]
THICKNESS_SCALE = tissue.THICKNESS_RANGE[1] - tissue.THICKNESS_RANGE[0]
"""m: a thickness ``t`` enters as ``(t - shift) / scale`` (:func:`stmpl.tissue.normalise`)."""

PRIOR_SCALE = 0.1
"""The linear prior's displacement as an input, in the units of a model's ``raw`` output over
this (with ``per_newton`` and 20 mm/N, 0.1 is 2 mm/N)."""

MIN_TOTAL_N = 1e-9
"""N: below this total force a scene is unloaded; a per-newton model's inputs are then zero."""


def total_force(force):
    """``(B,)`` total force (N) of ``(B, N)`` per-vertex force magnitudes."""
    return force.sum(-1)


def force_pattern(force):
    """``(B, N)`` per-vertex force divided by the scene's total (1 where loaded alone; zero for
    an unloaded scene).
    """
    return force / total_force(force).clamp_min(MIN_TOTAL_N)[:, None]


def load_channels(force, inv_area, per_newton: bool) -> list:
    """The load as ``(B, N)`` input channels from ``force`` ``(B, N)`` (N) and ``inv_area``
    ``(N,)`` (1 / vertex area, in whatever pressure unit the model wants): the pressure
    ``F_i / A_i``; or with ``per_newton`` the pressure per newton of the total, and the total
    force (N) on every vertex.
    """
    if per_newton:
        return [force_pattern(force) * inv_area, total_force(force)[:, None].expand_as(force)]
    return [force * inv_area]


def normalised_thickness(thickness):
    """``(B, N)`` thickness (m) over the tissue range, 0..1 (:func:`stmpl.tissue.normalise`)."""
    return tissue.normalise(thickness)
