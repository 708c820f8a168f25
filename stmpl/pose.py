"""A scene given by where an object is rather than by the force on the skin: what a VR, haptics
or robotics application knows. The answer to such a scene carries the deformation **and** the
force the object meets (per vertex, and its reaction).

A :class:`Pose` holds the rigid objects at their pose in the part's body coordinates
(:class:`Rigid`: a triangle mesh, m), the direction they press along, and the ``gap`` field the
learned models read: each rest skin vertex's signed distance to the objects (m), inside them
measured along the way they press (negative: how far the skin there must move along the press
to clear them, however deep; for objects that close each their own way, a grip, the signed
distance inside too), cut at :data:`GAP_REACH` away from them; and, where known, the ``way``
field: how the objects' surface nearest each rest skin vertex moves as they press. A grip's
fingers curl, so their surface sweeps along the skin as the hand closes, and friction drags the
skin with it: on the layered forearm the skin under the fingers moves mostly along itself, the
way the fingers sweep. The contact wing computes both (:mod:`stmpl.contact.gap`,
:func:`stmpl.contact.posing.posed`); this module only holds and checks them.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

GAP_REACH = 0.02
"""m: the gap field is cut at this distance from the objects (a skin vertex farther away is
not near any contact, and its distance carries no information)."""

REACH_TOLERANCE = 1e-6
"""m: a vertex is within reach of an object where its gap lies below :data:`GAP_REACH` by more
than this (the gap is cut at ``GAP_REACH``, and a float32 copy of the cut lies just below it)."""


def within_reach(gap) -> np.ndarray:
    """``(..., N)`` bool: the vertices an object lies within :data:`GAP_REACH` of, from their
    gap ``(..., N)`` (m, NumPy).
    """
    return np.asarray(gap, dtype=float) < GAP_REACH - REACH_TOLERANCE


@dataclass(frozen=True, eq=False)
class Rigid:
    """A rigid object at its pose: ``vertices`` ``(V, 3)`` in the part's body coordinates (m),
    ``faces`` ``(F, 3)`` with outward normals, and a ``name``. ``path`` ``(V, 3)``, optional:
    how far each vertex moves per metre as the object closes (a hand's grip, whose fingers
    close each its own way); without it the object presses along its pose's direction.
    """

    name: str
    vertices: np.ndarray
    faces: np.ndarray
    path: np.ndarray | None = None

    def __post_init__(self) -> None:
        if not isinstance(self.name, str) or not self.name.strip():
            raise ValueError(f"an object's name must be a non-empty string, got {self.name!r}")
        v = np.asarray(self.vertices, dtype=float)
        f = np.asarray(self.faces)
        if v.ndim != 2 or v.shape[1] != 3 or len(v) < 3:
            raise ValueError(f"object {self.name!r}: vertices must be (V >= 3, 3), got {v.shape}")
        if not np.isfinite(v).all():
            i = int(np.argmax(~np.isfinite(v).all(axis=1)))
            raise ValueError(f"object {self.name!r}: vertex {i} is not finite")
        if f.ndim != 2 or f.shape[1] != 3 or len(f) == 0 or f.dtype.kind not in "iu":
            raise ValueError(f"object {self.name!r}: faces must be a non-empty (F, 3) int array")
        if f.min() < 0 or f.max() >= len(v):
            raise ValueError(f"object {self.name!r}: faces index vertices outside 0..{len(v) - 1}")
        v, f = v.copy(), f.astype(np.int64)
        v.setflags(write=False)
        f.setflags(write=False)
        object.__setattr__(self, "vertices", v)
        object.__setattr__(self, "faces", f)
        if self.path is not None:
            p = np.array(self.path, dtype=float)
            if p.shape != v.shape or not np.isfinite(p).all():
                raise ValueError(
                    f"object {self.name!r}: path must be a finite {v.shape} array (m per m)"
                )
            p.setflags(write=False)
            object.__setattr__(self, "path", p)


def cut(gap: np.ndarray) -> np.ndarray:
    """A gap field (m, any shape) as a :class:`Pose` keeps it: cut at :data:`GAP_REACH` (a
    dataset keeps each distance as measured).
    """
    return np.minimum(gap, GAP_REACH)


class Pose:
    """Where the pressing objects are (see the module docstring).

    Attributes:
        gap: ``(N,)`` each rest skin vertex's signed distance to the objects, inside them
            along ``direction`` (a closing pose's: its signed distance), m (negative inside
            one), at most :data:`GAP_REACH`.
        direction: ``(3,)`` unit vector the objects press along (into the skin); ``None``
            for objects that close each along its own :attr:`Rigid.path` (a grip, whose
            reaction is the whole contact force: the squeeze).
        objects: the :class:`Rigid` objects at their pose; none where only the gap field is
            known (a dataset's sample: a learned model needs no more, the FEM refuses it).
        way: ``(N, 3)`` how the objects' surface nearest each rest skin vertex moves per metre
            the objects press or close (m per m: the direction itself for objects pressing
            along one; a grip's :attr:`Rigid.path` blended over its nearest vertices), zero
            where no object lies within :data:`GAP_REACH`; ``None`` where it is not known. A
            learned model with the option ``motion`` reads it beside the gap. It may be given
            as a function of no arguments that returns it: then it is computed (and checked)
            when first read, so a scene whose answer never reads it does not pay for it (a
            grip's costs a search of the hand's surface).

    A pose is read-only: its arrays cannot be written, nor its attributes set.
    """

    __slots__ = ("gap", "direction", "objects", "_way", "_way_of")

    def __init__(self, gap, direction, objects=(), way=None) -> None:
        g = np.asarray(gap, dtype=float)
        if g.ndim != 1:
            raise ValueError(f"Pose.gap must be one distance per vertex (N,), got {g.shape}")
        if not np.isfinite(g).all():
            i = int(np.argmax(~np.isfinite(g)))
            raise ValueError(f"Pose.gap is not finite at vertex {i} (value {g[i]})")
        if g.max(initial=0.0) > GAP_REACH * (1 + 1e-6):
            raise ValueError(
                f"Pose.gap must be cut at {1e3 * GAP_REACH:g} mm (GAP_REACH), got up to "
                f"{1e3 * g.max():.3g} mm"
            )
        objects = tuple(objects)
        if not all(isinstance(o, Rigid) for o in objects):
            raise ValueError("Pose.objects must be Rigid objects")
        d = None
        if direction is not None:
            d = np.array(direction, dtype=float)
            n = np.linalg.norm(d) if d.shape == (3,) else np.nan
            if not (np.isfinite(n) and abs(n - 1) < 1e-6):
                raise ValueError(f"Pose.direction must be a unit 3-vector, got {d.tolist()}")
            d.setflags(write=False)
        elif any(o.path is None for o in objects):
            lacking = next(o.name for o in objects if o.path is None)
            raise ValueError(
                f"Pose.direction is None (objects closing along their paths), and object "
                f"{lacking!r} has no path"
            )
        g.setflags(write=False)
        object.__setattr__(self, "gap", g)
        object.__setattr__(self, "direction", d)
        object.__setattr__(self, "objects", objects)
        object.__setattr__(self, "_way", None)
        object.__setattr__(self, "_way_of", way if callable(way) else None)
        if way is not None and not callable(way):
            object.__setattr__(self, "_way", self._checked_way(way))

    def __setattr__(self, name, value):
        raise AttributeError(f"a Pose is read-only: cannot set {name!r}")

    def __reduce__(self):
        return (Pose, (self.gap, self.direction, self.objects, self.way))

    def _checked_way(self, way) -> np.ndarray:
        w = np.array(way, dtype=float)
        if w.shape != (len(self.gap), 3):
            raise ValueError(f"Pose.way must be (N, 3) = {(len(self.gap), 3)}, got {w.shape}")
        if not np.isfinite(w).all():
            i = int(np.argmax(~np.isfinite(w).all(axis=1)))
            raise ValueError(f"Pose.way is not finite at vertex {i}")
        w.setflags(write=False)
        return w

    @property
    def way(self) -> np.ndarray | None:
        """The way field (see the class), computed on first read where it was given as a
        function.
        """
        if self._way is None and self._way_of is not None:
            object.__setattr__(self, "_way", self._checked_way(self._way_of()))
            object.__setattr__(self, "_way_of", None)
        return self._way

    @property
    def depth(self) -> float:
        """How far the objects reach into the rest skin at its deepest, m (0 if they do not)."""
        return float(max(-self.gap.min(), 0.0))

    @property
    def touched(self) -> np.ndarray:
        """``(K,)`` the rest skin vertices inside an object."""
        return np.flatnonzero(self.gap < 0)

    def near(self, within: float = 0.005) -> np.ndarray:
        """``(K,)`` the skin vertices within ``within`` (m) of the one nearest the objects: where
        they press, even between vertices (none inside them).
        """
        return np.flatnonzero(self.gap <= self.gap.min() + within)

    def nearest(self) -> str:
        """Where the skin's vertex nearest the objects lies, in words (the objects may press
        between vertices, where no vertex lies inside them).
        """
        g = float(self.gap.min())
        side = (
            "outside it" if g >= 0 else "inside it" if self.closing else "inside it along the press"
        )
        return f"the skin vertex nearest it {1e3 * abs(g):.2f} mm {side} at rest"

    @property
    def closing(self) -> bool:
        """Whether the objects close along their own paths (a grip) instead of one direction."""
        return self.direction is None

    @property
    def reaction_name(self) -> str:
        """What the reaction is called: a grip's is its ``"squeeze"`` (the whole contact force),
        a press's its ``"reaction"`` along the press.
        """
        return "squeeze" if self.closing else "reaction"

    def arrays(self) -> dict:
        """The pose as named arrays (for a scene file); :meth:`from_arrays` reads them (a
        closing pose's direction is kept as an empty array).
        """
        d = np.zeros(0) if self.direction is None else self.direction
        out = {"gap": self.gap, "direction": d}
        if self.way is not None:
            out["way"] = self.way
        for k, o in enumerate(self.objects):
            out[f"object{k}/vertices"] = o.vertices
            out[f"object{k}/faces"] = o.faces
            if o.path is not None:
                out[f"object{k}/path"] = o.path
        return out

    def names(self) -> list[str]:
        return [o.name for o in self.objects]

    @classmethod
    def from_arrays(cls, arrays: dict, names: list[str]) -> "Pose":
        objects = tuple(
            Rigid(
                n,
                arrays[f"object{k}/vertices"],
                arrays[f"object{k}/faces"],
                arrays.get(f"object{k}/path"),
            )
            for k, n in enumerate(names)
        )
        d = np.asarray(arrays["direction"])
        way = arrays.get("way")
        return cls(arrays["gap"], None if d.size == 0 else d, objects, way)
