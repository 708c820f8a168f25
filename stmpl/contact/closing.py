"""anny's hand closing on a limb: a grip as a rigid mesh that closes along a path.

The hand is set around the limb as in the paper's grasps (:func:`stmpl.contact.hand.grasp`),
smoothed by Loop's subdivision (anny's hand has edges of 1.5-11 mm), and closes along a path:
each vertex on the straight line between the hand set 1 mm and ``reach`` deep, carried back
until the hand clears the skin. Its pose at a depth ``d`` is that hand closed ``d`` (m) further.
"""

from __future__ import annotations

import numpy as np

from stmpl.contact.grips import GRIPS
from stmpl.contact.hand import Hand, SkinDistance, grasp, kept_file
from stmpl.files import atomic_savez
from stmpl.part import BodyPart
from stmpl.pose import Rigid

CLOSING_CACHE = 1
"""The version of :func:`closing_grip`'s answers kept on disk (:func:`cached_closing_grip`); a
change to what it returns raises it, and older files are then not read."""

OPEN = 0.01
"""m: how far back along its path a grip may open to clear the skin."""


def closing_grip(
    part: BodyPart,
    hand: Hand,
    along: float = 0.5,
    around: float = 0.0,
    kind: str = "whole",
    reach: float = 0.008,
    subdivisions: int = 2,
) -> Rigid:
    """The ``hand`` of anny set around the limb ``part`` in a ``kind`` of grip (``along`` and
    ``around`` as for :func:`~stmpl.contact.hand.grasp`), at first touch (its nearest point on
    the skin) with the :attr:`~stmpl.pose.Rigid.path` it closes along (m per m). ``reach``: how
    deep (m, in [2, 10) mm) the straight path is drawn to, or less where a finger of the grip
    cannot curl that deep (its joints run out: the tripod's middle finger on anny's left arm
    reaches 4 mm, and set 5 mm deep it stayed open 20 mm off the skin, so that a path drawn
    to it drew the finger back out of the limb); ``subdivisions``: Loop's, each
    quartering the hand's edges' length, so that the skin slides over rounded fingers. A hand
    that cuts into the limb however far it opens (a finger the grasp could not stretch clear)
    is refused, with the finger's name and depth.
    """
    if not (np.isfinite(reach) and 0.002 <= reach < 0.01):
        raise ValueError(f"reach must lie in [2, 10) mm, got {1e3 * reach:g} mm")
    first = 0.001
    near = grasp(part, hand, along, around, kind, depth=first)
    deep = _deepest(part, hand, along, around, kind, reach)
    reach = deep.depth
    from trimesh.remesh import subdivide_loop  # deferred: object meshes and closest points only

    # Loop's subdivision is linear in the vertices: the smoothed path is the path smoothed
    closer, faces = subdivide_loop(near.vertices, near.faces, iterations=subdivisions)
    path, _ = subdivide_loop(
        (deep.vertices - near.vertices) / (reach - first), near.faces, iterations=subdivisions
    )
    skin = SkinDistance(part)

    def clearance(back: float) -> np.ndarray:
        return skin(closer - back * path)

    lo, hi = 0.0, None
    for back in np.arange(0.0, OPEN + 1e-9, 0.0005):
        if clearance(back).min() >= 0:
            hi = back
            break
        lo = back
    if hi is None:
        d = clearance(OPEN)
        worst = int(np.argmin(d))
        j = int(np.argmin(np.linalg.norm(near.vertices - closer[worst], axis=1)))
        finger = next((f for f, ids in hand.finger_of.items() if j in ids), "palm")
        raise ValueError(
            f"the hand's {finger} lies {-1e3 * d[worst]:.1f} mm inside the skin however far the "
            f"{kind} grip opens (at {along:g} along, {around:g} around): choose another place "
            "or grip"
        )
    if hi > 0:
        for _ in range(20):
            mid = 0.5 * (lo + hi)
            lo, hi = (mid, hi) if clearance(mid).min() < 0 else (lo, mid)
    return Rigid(f"hand ({kind} grip)", closer - hi * path, faces, path)


def cached_closing_grip(
    part: BodyPart,
    phenotype: dict | None = None,
    side: str = "R",
    along: float = 0.5,
    around: float = 0.0,
    kind: str = "whole",
) -> Rigid:
    """:func:`closing_grip` of the ``side`` hand of the anny body of ``phenotype``, kept on
    disk (``$STMPL_CACHE_DIR/grips``) under the part's mesh, the hand and the placement: a grip
    made before is read back without running anny (setting a grip and its path takes some two
    hundred of its forward passes and as many distances to the skin: about 20 s).
    """
    if kind not in GRIPS:
        raise ValueError(f"grip must be one of {sorted(GRIPS)}, got {kind!r}")
    placement = [phenotype or {}, side, float(along), float(around), kind]
    f = kept_file("grips", part, [CLOSING_CACHE, placement])
    if f.is_file():
        with np.load(f) as z:
            return Rigid(str(z["name"]), z["vertices"], z["faces"], z["path"])
    grip = closing_grip(part, Hand(phenotype=phenotype, side=side), along, around, kind)
    arrays = {
        "name": np.array(grip.name),
        "vertices": np.asarray(grip.vertices, dtype=np.float64),
        "faces": np.asarray(grip.faces, dtype=np.int64),
        "path": np.asarray(grip.path, dtype=np.float64),
    }
    atomic_savez(f, arrays)
    return grip


def closed(grip: Rigid, depth: float) -> Rigid:
    """``grip`` closed ``depth`` (m) along its path."""
    if grip.path is None:
        raise ValueError(f"object {grip.name!r} has no path to close along")
    if not np.isfinite(depth):
        raise ValueError(f"a grip's depth must be finite (m), got {depth!r}")
    return Rigid(grip.name, grip.vertices + depth * grip.path, grip.faces, grip.path)


def _deepest(part, hand, along, around, kind, reach):
    """The grasp ``reach`` (m) deep, or the deepest in 1 mm steps down to 2 mm at which every
    finger of the grip reaches its depth; none: refused, naming the finger that does not.
    """
    depth = reach
    while True:
        g = grasp(part, hand, along, around, kind, depth=depth)
        short = [f for f in GRIPS[kind] if f not in g.reached]
        if not short:
            return g
        if depth - 0.001 < 0.002 - 1e-12:
            raise ValueError(
                f"the {kind} grip's {short[0]} cannot curl 2 mm into the limb at {along:g} "
                f"along, {around:g} around: choose another place or grip"
            )
        depth -= 0.001
