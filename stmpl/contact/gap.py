"""The gap a pressing object leaves the skin, measured along the way it presses: for each rest
skin vertex, how far the object's front lies from it along the press direction ``d`` (m).
Positive: the object would travel that far before it met the vertex; negative: the vertex lies
behind the front, inside the object, and the skin there must move that far along ``d`` to
clear it. Vertices off the object's track get :data:`~stmpl.pose.GAP_REACH`.

    gap_i = x_i . d - max{ s : a point of the object's surface on the line x_i + t d lies at s }

Unlike the signed distance (which inside a thin disk is at most the distance to its nearest
side), this is the depth the object pushes each vertex, however deep the press: under a disk's
face it is the disk's depth everywhere. A pose keeps the smaller of the two
(:func:`of_sample`, :func:`stmpl.contact.posing.posed`): inside an object the gap along the
press, which is the deeper; outside it the signed distance, which says how near the object
passes a vertex off its track (a ball between two vertices of a coarse mesh).
"""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

from stmpl.pose import GAP_REACH


def _unit(direction) -> np.ndarray:
    d = np.asarray(direction, dtype=float).reshape(3)
    n = float(np.linalg.norm(d))
    if not (np.isfinite(d).all() and n > 0):
        raise ValueError(f"a press direction must be a finite nonzero 3-vector, got {direction!r}")
    return d / n


def _cut(gap: np.ndarray, upto: float) -> np.ndarray:
    return np.minimum(np.nan_to_num(gap, nan=upto, posinf=upto), upto)


def ball(points, centre, radius: float, direction, upto: float = GAP_REACH) -> np.ndarray:
    """``(P,)`` the gap along ``direction`` (m) from ``points`` ``(P, 3)`` to a ball of
    ``radius`` (m) at ``centre`` ``(3,)``: its front at lateral distance ``rho`` from the axis
    lies ``sqrt(R^2 - rho^2)`` ahead of the centre.
    """
    d, x = _unit(direction), np.asarray(points, dtype=float).reshape(-1, 3)
    rel = x - np.asarray(centre, dtype=float)
    along = rel @ d
    rho2 = np.einsum("ij,ij->i", rel, rel) - along**2
    out = np.full(len(x), np.inf)
    hit = rho2 < radius**2
    out[hit] = along[hit] - np.sqrt(radius**2 - rho2[hit])
    return _cut(out, upto)


def disk(
    points, centre, radius: float, direction, rounding: float = 0.0, upto: float = GAP_REACH
) -> np.ndarray:
    """``(P,)`` the gap along ``direction`` (m) from ``points`` ``(P, 3)`` to a flat-ended
    cylinder of ``radius`` (m) pressing face-on, its face centred at ``centre`` ``(3,)``, its rim
    rounded by ``rounding`` (m): the face within ``radius - rounding`` of the axis, the rim's
    quarter circle beyond it.
    """
    d, x = _unit(direction), np.asarray(points, dtype=float).reshape(-1, 3)
    rel = x - np.asarray(centre, dtype=float)
    along = rel @ d
    rho = np.linalg.norm(rel - along[:, None] * d, axis=1)
    out = np.full(len(x), np.inf)
    flat = rho <= radius - rounding
    out[flat] = along[flat]
    rim = ~flat & (rho < radius)
    out[rim] = along[rim] + rounding - np.sqrt(rounding**2 - (rho[rim] - radius + rounding) ** 2)
    return _cut(out, upto)


def mesh(obj, points, direction, upto: float = GAP_REACH, chunk: int = 256) -> np.ndarray:
    """``(P,)`` the gap along ``direction`` (m) from ``points`` ``(P, 3)`` to a closed triangle
    mesh ``obj`` (``vertices``, ``faces``): each point's line along ``direction`` crosses the
    surface where, seen along it, the point lies in a triangle (barycentric coordinates in the
    plane across the press); its front is the farthest crossing.
    """
    d, x = _unit(direction), np.asarray(points, dtype=float).reshape(-1, 3)
    out = np.full(len(x), float(upto))
    v, f = np.asarray(obj.vertices, dtype=float), np.asarray(obj.faces)
    a = np.cross(d, [1.0, 0.0, 0.0] if abs(d[0]) < 0.9 else [0.0, 1.0, 0.0])
    a /= np.linalg.norm(a)
    across = np.stack([a, np.cross(d, a)], 1)  # (3, 2): the plane across the press
    q, s = x @ across, x @ d
    tri, ts = (v @ across)[f], (v @ d)[f]  # (F, 3, 2), (F, 3)
    lo, hi = tri.min(1), tri.max(1)
    near = np.flatnonzero((q >= lo.min(0)).all(1) & (q <= hi.max(0)).all(1) & (s - ts.max() < upto))
    e1, e2 = tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]
    det = e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0]
    ok = np.abs(det) > 1e-18  # triangles seen edge-on along the press cross no line
    tri, ts, e1, e2, det, lo, hi = (z[ok] for z in (tri, ts, e1, e2, det, lo, hi))
    for k in range(0, len(near), chunk):
        idx = near[k : k + chunk]
        r = q[idx, None, :] - tri[None, :, 0]  # (C, F, 2)
        b1 = (r[..., 0] * e2[:, 1] - r[..., 1] * e2[:, 0]) / det
        b2 = (e1[:, 0] * r[..., 1] - e1[:, 1] * r[..., 0]) / det
        inside = (b1 >= -1e-9) & (b2 >= -1e-9) & (b1 + b2 <= 1 + 1e-9)
        hit = ts[:, 0] + b1 * (ts[:, 1] - ts[:, 0]) + b2 * (ts[:, 2] - ts[:, 0])
        front = np.where(inside, hit, -np.inf).max(1)
        out[idx] = _cut(s[idx] - front, upto)
    return out


def of_press(points, kind: str, params: dict, upto: float = GAP_REACH) -> np.ndarray:
    """``(P,)`` the gap along the press of a dataset's pressed object (``kind``
    ``press_disk`` or ``press_sphere``; ``params`` its ``radius``, ``rounding``, posed
    ``centre`` and ``direction``, as a sample records them).
    """
    try:
        centre, radius, d = params["centre"], float(params["radius"]), params["direction"]
    except (KeyError, TypeError) as e:
        raise ValueError(f"a {kind} sample does not record its object's pose ({e})") from e
    if kind == "press_sphere":
        return ball(points, centre, radius, d, upto)
    if kind == "press_disk":
        return disk(points, centre, radius, d, float(params.get("rounding", 0.0)), upto)
    raise ValueError(f"the gap along a press knows disks and balls, not {kind!r}")


PRESSED = ("press_disk", "press_sphere")
"""The dataset kinds whose pose :func:`of_sample` measures along the press."""


def of_sample(points, kind: str, params: dict, stored) -> np.ndarray:
    """``(P,)`` the gap field a pose model reads for a dataset sample: for a pressed disk or
    ball the smaller of the gap along the press (:func:`of_press`) and the sample's ``stored``
    signed distance; for a grip (each finger closing its own way) the signed distance; cut at
    :data:`~stmpl.pose.GAP_REACH`.
    """
    signed = np.minimum(np.asarray(stored, dtype=float), GAP_REACH)
    if kind in PRESSED:
        return np.minimum(of_press(points, kind, params), signed)
    return signed


WAY_NEIGHBOURS = 3
"""How many of the nearest object vertices a closing pose's way blends (:func:`way`)."""


def blended(path, distances, nearest) -> np.ndarray:
    """``(P, 3)`` the paths ``path`` ``(V, 3)`` of each point's ``K`` nearest object vertices
    (``nearest`` ``(P, K + 1)`` indices, ``distances`` ``(P, K + 1)`` m, ascending), weighted
    by how much nearer each lies than the ``(K + 1)``-th: ``w_j = d_{K+1} - d_j``. A vertex's
    weight falls to zero as it stops being among the ``K`` nearest, so the way changes
    continuously as a point moves across the object (the single nearest vertex's path jumps
    where two vertices are equally near); all ``K + 1`` equally near: their mean.
    """
    d = np.asarray(distances, dtype=float)
    w = d[:, -1:] - d
    tied = w.sum(1) <= 0.0
    w[tied] = 1.0  # every one of the K + 1 as near: their mean, whichever K the search chose
    return np.einsum("pk,pki->pi", w / w.sum(1, keepdims=True), np.asarray(path, float)[nearest])


def way(points, gap, direction=None, objects=()) -> np.ndarray:
    """``(P, 3)`` the way field of a pose (:attr:`stmpl.pose.Pose.way`, m per m) on the rest
    skin ``points`` ``(P, 3)`` with gap field ``gap`` ``(P,)`` (m): the press ``direction``
    ``(3,)`` where an object lies within :data:`~stmpl.pose.GAP_REACH`; objects that close
    along their own paths (``direction`` None; :class:`~stmpl.pose.Rigid` with a ``path``):
    the paths of the :data:`WAY_NEIGHBOURS` object vertices nearest each point there,
    :func:`blended` so that the field is continuous. Zero elsewhere.
    """
    x = np.asarray(points, dtype=float).reshape(-1, 3)
    g = np.asarray(gap, dtype=float).reshape(-1)
    if len(g) != len(x):
        raise ValueError(f"gap must hold one distance per point ({len(x)}), got {len(g)}")
    out = np.zeros((len(x), 3))
    near = np.flatnonzero(g < GAP_REACH)
    if direction is not None:
        out[near] = _unit(direction)
        return out
    if any(o.path is None for o in objects) or not objects:
        raise ValueError("a closing pose's way needs its objects, each with its path")
    v = np.concatenate([o.vertices for o in objects])
    path = np.concatenate([o.path for o in objects])
    if len(near):  # a Rigid has at least three vertices: the query's answers are (P, k)
        k = min(WAY_NEIGHBOURS + 1, len(v))
        distances, nearest = cKDTree(v).query(x[near], k=k)
        out[near] = blended(path, distances, nearest)
    return out
