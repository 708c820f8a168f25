"""Input features every learned model shares, defined once: the load as pressure (or, per
newton, its pattern and the total force), or an object's pose as the gap field, the thickness
normalised over the tissue range, and the scale of the linear prior's displacement as an input.
Torch tensors, SI units in; and a pose model's answer read from its pressure outputs.
"""

from __future__ import annotations

import numpy as np

from stmpl import tissue
from stmpl.pose import GAP_REACH
from stmpl.scene import Scene

PRESSURE_SCALE = 1000.0
"""Pa: pressure inputs are divided by this (the tissue's Young's modulus in the paper)."""

THICKNESS_SHIFT = tissue.THICKNESS_RANGE[0]
THICKNESS_SCALE = tissue.THICKNESS_RANGE[1] - tissue.THICKNESS_RANGE[0]
"""m: a thickness ``t`` enters as ``(t - shift) / scale`` (:func:`stmpl.tissue.normalise`)."""

PRIOR_SCALE = 0.1
"""The linear prior's displacement as an input, in the units of a model's ``raw`` output over
this (with ``per_newton`` and 20 mm/N, 0.1 is 2 mm/N)."""

CORRECTION_SCALE = 0.05
"""On top of a prior the network's output is a correction in units of this share of ``raw``'s:
corrections are a few per cent of the answer, and at full scale Adam's first steps would throw
the prediction far from the prior before it learned anything (:mod:`models.prior`)."""

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


HOLDING = ("held", "closure")
"""The priors that hold the skin near the objects: ``held`` at the network's answer plus the
contact prior, ``closure`` at the network's answer plus the linear FEM's closure of the objects
(:meth:`fem.holding.HeldSkin.closure`)."""


def runs_held_only(config: dict) -> bool:
    """Whether a network of options ``config`` answers only the held vertices (a held prior,
    :data:`HOLDING`): the held prior reads the network's answer there alone and no contact lies
    beyond them, so the network runs on their subgraph (those vertices and ``steps`` hops more)
    at every fidelity, the answer it gives on the whole part (and in training the same
    gradient).
    """
    return config.get("prior") in HOLDING


GAP_SCALE = 0.01
"""m: how deep an object reaches into the rest skin enters over this (a pose's input)."""

PRESSURE_OUT_SCALE = 1e4
"""Pa: a pose model answers the contact pressure in units of this (10 kPa: a few newtons on a
square centimetre)."""

CONTACT_BAND = 0.008
"""m: a pose model's contact force is answered on the vertices within this of an object at rest,
and tapered to none over :data:`CONTACT_TAPER` beyond it: the skin moves in under a press, not
out towards the object, but a vertex one edge from the touching ones carries its share of the
contact force (on anny's belly, edges of about 10 mm, 6 % of the force lies on vertices 5-7.5 mm
from the object at rest, none farther)."""

CONTACT_TAPER = 0.002
"""m: beyond :data:`CONTACT_BAND` a vertex's share of the answered contact force falls linearly
to none over this, so that an object's reaction moves continuously with its depth and force
control finds every force between two depths. With a hard edge it jumped as vertices crossed
it (an untrained model's reaction on a grip rose in steps of 0.04-0.13 N, each where a vertex
entered the band, and no depth gave 1 N)."""


def contact_weight(gap):
    """Each vertex's share of its answered contact force from the gap field ``gap`` (m; NumPy
    or torch, any shape): 1 within :data:`CONTACT_BAND` of an object, none beyond
    :data:`CONTACT_TAPER` more, linear between.
    """
    return ((CONTACT_BAND + CONTACT_TAPER - gap) / CONTACT_TAPER).clip(0.0, 1.0)


PRESSURE_LOG_MAX = 8.0
"""The largest log-pressure a pose model answers (e^8 x 10 kPa, 30 MPa: far past any contact the
tissue carries), so that an untrained network cannot overflow."""


def pressure_out(raw):
    """A pose model's pressure channels ``(..., 2)`` in units of :data:`PRESSURE_OUT_SCALE` from
    its raw outputs: their exponential. A contact pressure grows some fortyfold from a light
    touch to a firm press as the tissue stiffens, and a network's output, whose scale grows by
    small steps, meets such a range in its logarithm (read linearly it stayed at a tenth of the
    deepest presses' pressures after training); never negative, as contact only pushes.
    """
    return raw.clamp_max(PRESSURE_LOG_MAX).exp()


def gap_channels(gap) -> list:
    """An object's pose as two ``(B, N)`` input channels from the gap field ``gap`` ``(B, N)``
    (m, negative inside an object): how deep each vertex lies inside (m), and how far outside,
    cut at :data:`stmpl.pose.GAP_REACH` (m).
    """
    return [(-gap).clamp_min(0.0), gap.clamp(0.0, GAP_REACH)]


def gap_of(given):
    """``(B, N)`` the gap field (m) of a pose model's input ``given`` (NumPy or torch): the
    input itself, or with the option ``motion`` the first of its ``(B, N, 4)`` channels.
    """
    return given[..., 0] if given.ndim == 3 else given


def way_channels(given) -> list:
    """The way the objects move (:attr:`stmpl.pose.Pose.way`, m per m) as three ``(B, N)``
    input channels of a pose model's input ``given`` ``(B, N, 4)`` (option ``motion``); none of
    a gap field alone ``(B, N)``.
    """
    return [given[..., k] for k in (1, 2, 3)] if given.ndim == 3 else []


def near_objects(gap):
    """``(B, N)`` a field (NumPy or torch) that is positive on the vertices an answer's contact
    force reaches (:func:`contact_weight`), from the gap field ``gap`` (m): where a pose loads
    the skin, as a force field marks it for the regions of :mod:`stmpl.reach`.
    """
    return (CONTACT_BAND + CONTACT_TAPER - gap).clip(min=0.0)


CONTACT_FLOOR = 0.01
"""Below this share of an answer's peak, a pose model's contact pressure is read as no contact.
The network's pressure (an exponential) never reaches zero, while the FEM's contact has an edge:
on the grip set's test and validation grips the pressure above 1 % of the answer's peak lies
on about the FEM's contact vertices (7-61 of them, against 7-59), and the tail below it
carries 0.4-0.7 % of the force (median; at most 3.5 %). Without it, a whole hand's answer
touched every vertex within 8 mm of the hand, and its contact's area lay five times past any
the FEM had seen."""


def squeezes(config: dict) -> bool:
    """Whether a pose model of options ``config`` has its contact forces summed for its
    reaction (option ``reaction: pressure``, :data:`models.trained.REACTIONS`: a grip's
    squeeze) rather than its push channel.
    """
    return config.get("reaction", "push") == "pressure"


def posed_answer(
    scene: Scene, u: np.ndarray, pressure: np.ndarray, push: np.ndarray, squeeze: bool = False
) -> dict:
    """A pose model's answer to ``scene``: displacement ``u`` ``(N, 3)`` m, the contact force on
    each vertex from ``pressure`` ``(N,)`` Pa (the network's; below :data:`CONTACT_FLOOR` of its
    peak where contact is answered read as none) and the reaction from ``push`` ``(N,)`` Pa (the
    network's pressure along the press direction, the reaction's density), both weighed by
    :func:`contact_weight`: whole within :data:`CONTACT_BAND` of the objects, tapered to none
    beyond. ``squeeze``: the reaction is the contact forces summed instead (a grip's squeeze,
    option ``reaction: pressure``, :data:`models.trained.REACTIONS`).
    """
    share = contact_weight(scene.pose.gap) * scene.part.vertex_areas
    pressure = np.maximum(pressure, 0.0)
    peak = pressure[share > 0].max(initial=0.0)  # the peak where contact is answered
    pressure = np.where(pressure >= CONTACT_FLOOR * peak, pressure, 0.0)
    force = pressure * share
    reaction = float(force.sum()) if squeeze else float(np.sum(push * share))
    return {"displacement": u, "force": force, "reaction": reaction}
