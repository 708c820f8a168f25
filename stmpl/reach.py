"""What a scene needs: how far a load's influence reaches over a body part.

A press moves the tissue within a few thicknesses of the contact; the rest of the part stays put
to well under a percent of the deepest displacement. Every predictor that models no more than a
scene needs (``fidelity="auto"``) cuts the part with the functions here:

- the local FEM solves the patch within :func:`first_margin` of the load (:func:`near`), holds
  the cut, and grows the margin by :data:`GROW` while the vertices next to the cut move more
  than :data:`RING_TOLERANCE` of the deepest displacement;
- the linear FEM's columns are solved on such patches too;
- a learned model on the linear prior answers where the prior moves the tissue by more than
  :data:`REGION_TOLERANCE` of its deepest (:func:`moved`), the prior elsewhere; the GNN runs on
  that region grown by one ring per message-passing step (:func:`hops`), the UV-UNet on the
  window of its chart that covers it.

Distances in metres; masks are boolean over the part's vertices, ``(N,)`` or ``(B, N)`` for a
batch of scenes.
"""

from __future__ import annotations

import weakref

import numpy as np
from scipy.spatial import cKDTree

from stmpl.part import BodyPart

THICKNESSES = 6.0
"""The first margin: the contact's radius plus this many times its largest thickness."""
GROW = 1.5
"""Margin factor from one attempt to the next when a cut was too tight."""
RING_TOLERANCE = 0.005
"""How far the vertices next to a cut may move, relative to the deepest displacement."""
REGION_TOLERANCE = 0.01
"""A learned model answers where its prior moves the tissue by more than this share of the
prior's deepest displacement (and one ring of vertices wider); the prior alone answers
elsewhere."""

_ADJACENCY: "weakref.WeakKeyDictionary" = weakref.WeakKeyDictionary()
"""Each part's vertex adjacency as float32 (for sparse products), kept while the part lives."""


def first_margin(
    part: BodyPart, thickness: np.ndarray, force: np.ndarray, thicknesses: float = THICKNESSES
) -> float:
    """The first cut's margin, m: the radius of the loaded region (half its largest extent,
    capped at 5 cm) plus ``thicknesses`` times the thickest tissue under it.

    Shapes: ``thickness`` ``(N,)`` m, ``force`` ``(N,)`` N.
    """
    loaded = np.flatnonzero(force > 0)
    if len(loaded) == 0:
        raise ValueError("the load has no loaded vertex (force is zero everywhere)")
    x = part.vertices[loaded]
    extent = float(np.linalg.norm(x.max(0) - x.min(0)))
    return min(0.5 * extent, 0.05) + thicknesses * float(np.max(thickness[loaded]))


def near(part: BodyPart, force: np.ndarray, margin: float) -> np.ndarray:
    """``(N,)`` mask of the vertices within ``margin`` (m, straight line) of a loaded vertex
    (``force`` ``(N,)`` > 0).
    """
    loaded = np.flatnonzero(force > 0)
    if len(loaded) == 0:
        raise ValueError("the load has no loaded vertex (force is zero everywhere)")
    tree = cKDTree(part.vertices[loaded])
    return tree.query(part.vertices, distance_upper_bound=margin)[0] <= margin


def adjacency(part: BodyPart):
    """The part's ``(N, N)`` vertex adjacency as a float32 sparse matrix (cached per part)."""
    a = _ADJACENCY.get(part)
    if a is None:
        a = _ADJACENCY[part] = part.adjacency.astype(np.float32)
    return a


def grown(part: BodyPart, mask: np.ndarray, rings: int) -> np.ndarray:
    """``mask`` (``(N,)`` or ``(B, N)``) grown by ``rings`` rings of mesh neighbours."""
    a = adjacency(part)
    m = np.asarray(mask, bool)
    for _ in range(rings):
        m = m | (a @ m.T.astype(np.float32) > 0).T
    return m


def hops(part: BodyPart, mask: np.ndarray, steps: int) -> np.ndarray:
    """``(B, N)`` int: 0 on ``mask`` ``(B, N)``, ``k`` on the vertices ``k`` rings of mesh
    neighbours from it (``k <= steps``), ``steps + 1`` beyond.
    """
    level = np.where(mask, 0, steps + 1)
    sub = np.asarray(mask, bool)
    for k in range(1, steps + 1):
        wider = grown(part, sub, 1)
        level[wider & ~sub] = k
        sub = wider
    return level


def moved(
    part: BodyPart,
    force: np.ndarray,
    displacement: np.ndarray,
    rings: int = 1,
    tolerance: float = REGION_TOLERANCE,
) -> np.ndarray:
    """``(B, N)`` mask of the loaded vertices (``force`` ``(B, N)`` > 0) and of those that
    ``displacement`` ``(B, N, 3)`` (m; the linear prior's answer) moves by more than
    ``tolerance`` of its deepest (:func:`moving`), grown by ``rings`` rings of mesh neighbours.
    An unloaded scene moves nothing.
    """
    return grown(part, moving(force, displacement, tolerance), rings)


def moving(
    force: np.ndarray, displacement: np.ndarray, tolerance: float = REGION_TOLERANCE
) -> np.ndarray:
    """:func:`moved` before its rings: the loaded vertices and those ``displacement`` moves by
    more than ``tolerance`` of its deepest, ``(B, N)``.
    """
    mag = np.einsum("...i,...i->...", displacement, displacement)  # squared
    m = (force > 0) | (mag > tolerance**2 * mag.max(-1, keepdims=True))
    m &= (force > 0).any(-1, keepdims=True)
    return m


def within_margin(part: BodyPart, thickness: np.ndarray, force: np.ndarray) -> np.ndarray:
    """``(B, N)``: per scene (``thickness``, ``force`` ``(B, N)``) the vertices within
    :func:`first_margin` of its load, counted in rings of mesh neighbours of the part's median
    edge length (a region without a prior to judge by).
    """
    e = part.edges
    edge = float(np.median(np.linalg.norm(np.diff(part.vertices[e], axis=1)[:, 0], axis=1)))
    out = np.zeros(force.shape, bool)
    for b in range(len(force)):
        m = force[b] > 0
        if m.any():
            rings = int(np.ceil(first_margin(part, thickness[b], force[b]) / edge))
            out[b] = grown(part, m, rings)
    return out
