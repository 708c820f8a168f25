"""Where scenes lie together, and what was measured there: the joint support of a predictor's data
and the out-of-sample evidence of its errors.

A per-axis box (:class:`stmpl.envelope.Envelope`) admits combinations its data never held: a
heavy force on a small area at the thinnest tissue, each alone inside its range. Here every scene
is a point in :data:`COORDS` (the logarithms of its force, area and pressures, its thickness and
number of contacts), scaled by the spread of the training scenes, and a new scene is judged by
its neighbours:

- **support**: it lies within :attr:`Support.reach` of a training scene, or of a scene measured
  out of sample that kept the promise (the reach: the distance within which 95 % of the training
  scenes find another);
- **evidence**: among the scenes the predictor was measured on out of sample (its validation
  split, and test sets measured later), the :data:`NEIGHBOURS` nearest within
  :attr:`Support.evidence_reach` kept the per-scene promise
  (:data:`stmpl.envelope.SCENE_PROMISE`) with room to spare: their errors at most
  :data:`MARGIN` of it. A scene whose measured neighbours came closer to breaking it, or that
  has none near, lies outside: a promise is backed by measurement, not by data alone.

>>> s = Support.of(points)                    # (S, D) training scenes' coordinates
>>> s.measure(points_val, kept, errors)        # out-of-sample evidence
>>> s.reasons(coordinates(features(part, t, f)))   # [] inside, else one sentence
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy.spatial import cKDTree

COORDS = ("thickness", "force", "area", "pressure", "peak_pressure", "contacts")
"""A scene's coordinates: its mean thickness (mm), the largest force of a contact (N), the total
contact area (cm^2), the highest mean pressure of a contact and the highest pressure on a vertex
(kPa), all as natural logarithms, and the number of contacts."""
ONE_SIDED = np.array([False, True, False, True, True, True])
"""The coordinates along which a lighter load is no harder to answer (force, pressures,
contacts): a scene is supported by a data scene at least as intense there, as the per-axis box
bounds these axes at the top only. Thickness and area count both ways."""
QUANTILE = 0.95
"""The share of training scenes that find a neighbour within :attr:`Support.reach`, and of them
that find a measured scene within :attr:`Support.evidence_reach`."""
NEIGHBOURS = 2
"""How many measured scenes (the nearest, within the evidence reach) must back an answer."""
MARGIN = 0.5
"""The share of the per-scene promise the backing scenes' errors may reach (relative MEE and
peak error each). An answer's error is not its neighbours': on the small ablation (a GNN, a
UV-UNet and the linear FEM trained on 27 disk and ellipse placements of the arm), scenes whose
nearest measured neighbour kept the promise still broke it in 14 of 65 test scenes, since the
place a load presses is not among the coordinates; with two neighbours within half the
promise, none of the 65 answers then said inside broke it (37, 17 and 11 of 102 test scenes
inside). Chosen there, it is to be measured again on scenes no envelope was fitted on."""
MAX_POINTS = 4096
"""Support points kept (farthest-point thinning above it: a checkpoint stays small)."""


def coordinates(feat: dict) -> np.ndarray:
    """``(D,)`` the coordinates (:data:`COORDS`) of a scene's features
    (:func:`stmpl.envelope.features`); an unloaded scene sits at a force of 1 mN.
    """
    force = max(feat["contact_force"], default=0.0)
    area = sum(feat["contact_area"])
    pressure = max(feat["contact_pressure"], default=0.0)
    return np.array(
        [
            np.log(1e3 * float(np.mean(feat["thickness"]))),
            np.log(max(force, 1e-3)),
            np.log(max(1e4 * area, 1e-3)),
            np.log(max(1e-3 * pressure, 1e-3)),
            np.log(max(1e-3 * feat["peak_pressure"], 1e-3)),
            float(feat["contacts"]),
        ]
    )


def _num(x: float, digits: int) -> float | None:
    """``x`` rounded for JSON, ``None`` for NaN (JSON has no NaN)."""
    return round(float(x), digits) if np.isfinite(x) else None


def _thin(points: np.ndarray, keep: int) -> np.ndarray:
    """Indices of ``keep`` rows of ``points`` spread over them (farthest-point order)."""
    chosen = [0]
    d = np.sqrt(((points - points[0]) ** 2).sum(1))
    for _ in range(keep - 1):
        k = int(d.argmax())
        chosen.append(k)
        d = np.minimum(d, np.sqrt(((points - points[k]) ** 2).sum(1)))
    return np.array(sorted(chosen))


@dataclass
class Support:
    """Training scenes and measured scenes as scaled points (see the module's notes)."""

    scale: np.ndarray  # (D,) the training scenes' spread per coordinate (1 where none)
    points: np.ndarray  # (M, D) training scenes, scaled
    reach: float
    measured: np.ndarray = field(default_factory=lambda: np.zeros((0, len(COORDS))))
    kept: np.ndarray = field(default_factory=lambda: np.zeros(0, bool))
    errors: np.ndarray = field(default_factory=lambda: np.zeros((0, 2)))  # rel. MEE, peak err %
    evidence_reach: float = float("nan")
    sources: list = field(default_factory=list)
    promise: tuple = (1.5, 10.0)  # what the evidence was judged by: rel. MEE %, peak %
    _trees: dict = field(default_factory=dict, init=False, repr=False, compare=False)

    def _tree(self, which: str) -> cKDTree:
        """The KD-tree of ``measured``, built once."""
        if which not in self._trees:
            self._trees[which] = cKDTree(getattr(self, which))
        return self._trees[which]

    def _backing(self) -> np.ndarray:
        """The scenes that support an answer: the training scenes and the measured ones that
        kept the promise.
        """
        if "backing" not in self._trees:
            self._trees["backing"] = np.vstack([self.points, self.measured[self.kept]])
        return self._trees["backing"]

    def distance(self, coords: np.ndarray) -> float:
        """How far (scaled) a scene at ``coords`` ``(D,)`` lies from the nearest scene backing
        it, counting only the excess along :data:`ONE_SIDED` coordinates.
        """
        diff = np.asarray(coords, dtype=float) / self.scale - self._backing()
        diff[:, ONE_SIDED] = np.maximum(diff[:, ONE_SIDED], 0.0)
        return float(np.sqrt((diff * diff).sum(1).min()))

    @classmethod
    def of(cls, coords: np.ndarray) -> "Support":
        """The support of training scenes ``coords`` ``(S, D)`` (:func:`coordinates`)."""
        c = np.asarray(coords, dtype=float)
        if c.ndim != 2 or c.shape[1] != len(COORDS) or len(c) == 0:
            raise ValueError(f"support needs (S, {len(COORDS)}) coordinates, got {c.shape}")
        if not np.all(np.isfinite(c)):
            raise ValueError("support coordinates must be finite")
        spread = c.std(0)
        scale = np.where(spread > 1e-6, spread, 1.0)
        pts = np.unique(np.round(c / scale, 6), axis=0)
        if len(pts) > MAX_POINTS:
            pts = pts[_thin(pts, MAX_POINTS)]
        if len(pts) > 1:
            d, _ = cKDTree(pts).query(pts, k=2)  # itself, then its nearest other
            reach = float(np.quantile(d[:, 1], QUANTILE))
        else:
            reach = 0.0
        return cls(scale, pts, max(reach, 1e-6))

    def measure(self, coords, kept, errors, source: str = "", promise=None) -> None:
        """Add out-of-sample evidence: scenes ``coords`` ``(S, D)``, whether each kept the
        promise ``(S,)`` and its relative MEE and peak error ``(S, 2)`` (%); the evidence
        reach is set again over all measured scenes. ``promise``: ``(relative MEE, peak)`` %,
        the per-scene promise they were judged by (kept from the first evidence on).
        """
        if promise is not None:
            promise = (float(promise[0]), float(promise[1]))
            if len(self.measured) and promise != tuple(self.promise):
                raise ValueError(
                    f"evidence judged by promise {promise} cannot join evidence judged by "
                    f"{tuple(self.promise)}"
                )
            self.promise = promise
        c = np.asarray(coords, dtype=float) / self.scale
        kept = np.asarray(kept, dtype=bool)
        errors = np.asarray(errors, dtype=float).reshape(-1, 2)
        if c.ndim != 2 or c.shape[1] != len(COORDS) or not (len(c) == len(kept) == len(errors)):
            raise ValueError(
                f"evidence needs (S, {len(COORDS)}) coordinates, (S,) kept and (S, 2) errors, "
                f"got {c.shape}, {kept.shape}, {errors.shape}"
            )
        self.measured = np.vstack([self.measured, c])
        self._trees.clear()
        self.kept = np.concatenate([self.kept, kept])
        self.errors = np.vstack([self.errors, errors])
        if source:
            self.sources.append({"source": source, "scenes": int(len(c))})
        d, _ = self._tree("measured").query(self.points, k=1)
        self.evidence_reach = max(float(np.quantile(d, QUANTILE)), self.reach)

    def reasons(self, coords: np.ndarray) -> list[str]:
        """Why a scene at ``coords`` ``(D,)`` is not backed: ``[]`` when it lies within reach of
        the training scenes and its nearest measured scene kept the promise.
        """
        q = np.asarray(coords, dtype=float) / self.scale
        if "backing tree" not in self._trees:
            self._trees["backing tree"] = cKDTree(self._backing())
        near, _ = self._trees["backing tree"].query(q)  # at least the one-sided distance
        d = near if near <= self.reach * (1 + 1e-9) else self.distance(coords)
        if d > self.reach * (1 + 1e-9):
            return [
                f"no scene in the data combines its thickness, force, area and pressures: the "
                f"nearest lies {d / self.reach:.2f} x the data's spacing away"
            ]
        if not len(self.measured):
            return []
        k = min(NEIGHBOURS, len(self.measured))
        e, i = self._tree("measured").query(q, k=k)
        e, i = np.atleast_1d(e), np.atleast_1d(i)
        if e[0] > self.evidence_reach * (1 + 1e-9):
            return [
                f"no scene measured out of sample lies near (the nearest "
                f"{e[0] / self.evidence_reach:.2f} x the evidence's reach away)"
            ]
        near = i[e <= self.evidence_reach * (1 + 1e-9)]
        rel, peak = self.errors[near, 0], self.errors[near, 1]
        if not np.all(np.isfinite(rel) & np.isfinite(peak)):
            return ["a scene measured out of sample near it is one the FEM could not solve"]
        shares = np.maximum(rel / self.promise[0], np.abs(peak) / self.promise[1])
        worst = int(np.argmax(shares))
        share = float(shares[worst])
        if share > MARGIN:
            verb = "broke the promise" if share > 1 else "came near breaking the promise"
            return [
                f"a scene measured out of sample near it {verb} (relative MEE "
                f"{rel[worst]:.2f} %, peak {peak[worst]:+.1f} %; answers are backed where "
                f"measured errors stay within {MARGIN:g} of it)"
            ]
        return []

    def to_dict(self) -> dict:
        r = lambda a: np.round(np.asarray(a, dtype=float), 5).tolist()  # noqa: E731
        return {
            "coords": list(COORDS),
            "scale": r(self.scale),
            "points": r(self.points),
            "reach": float(self.reach),
            "measured": r(self.measured),
            "kept": [bool(k) for k in self.kept],
            "errors": [[_num(x, 3) for x in e] for e in self.errors],
            "evidence_reach": None if not np.isfinite(self.evidence_reach) else self.evidence_reach,
            "sources": list(self.sources),
            "promise": list(self.promise),
        }

    @classmethod
    def from_dict(cls, d: dict) -> "Support":
        """From :meth:`to_dict`'s output, checked; ``ValueError`` names what is wrong."""
        if not isinstance(d, dict) or d.get("coords") != list(COORDS):
            raise ValueError(f"an envelope's support must have coordinates {list(COORDS)}")
        try:
            n = len(COORDS)
            s = cls(
                np.asarray(d["scale"], dtype=float).reshape(n),
                np.asarray(d["points"], dtype=float).reshape(-1, n),
                float(d["reach"]),
                np.asarray(d.get("measured") or [], dtype=float).reshape(-1, n),
                np.asarray(d.get("kept") or [], dtype=bool),
                np.array(
                    [[np.nan if x is None else x for x in e] for e in d.get("errors") or []],
                    dtype=float,
                ).reshape(-1, 2),
                float(d["evidence_reach"]) if d.get("evidence_reach") is not None else np.nan,
                list(d.get("sources") or []),
                tuple(float(x) for x in d.get("promise", (1.5, 10.0))),
            )
        except (KeyError, TypeError, ValueError) as e:
            raise ValueError(f"an envelope's support is unreadable: {e}") from e
        if not (len(s.measured) == len(s.kept) == len(s.errors)) or len(s.points) == 0:
            raise ValueError("an envelope's support has mismatched evidence or no points")
        if not (np.all(np.isfinite(s.points)) and np.all(s.scale > 0) and s.reach > 0):
            raise ValueError("an envelope's support has non-finite points or scales")
        return s
