"""Where a predictor's answers are backed by data: the support of its training scenes (and of the
test sets it was measured on), and the check of a new scene against it.

A scene is described by what shapes its answer: the tissue thickness, and for every contact (a
connected patch of loaded vertices) its total force, area and mean pressure, the highest
per-vertex pressure, and the number of contacts. An :class:`Envelope` holds, per axis, the
range those quantities took in the data, in one or more named boxes (``training``, then any
test set a model was measured on and met its promise); a scene lies inside when it fits one box
on every axis. Pressures and areas do not depend on the mesh resolution; per-vertex forces do,
and are not an axis.

>>> env = Envelope.of(part, thickness, force, name="training")   # (S, N) arrays
>>> env.reasons(scene)   # [] inside, else one sentence per axis it leaves
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from stmpl.part import BodyPart
from stmpl.support import Support, coordinates

FORMAT = "stmpl-envelope/1"

AXES = {
    # name: (kind, unit, scale for printing, what it is)
    "thickness": ("range", "mm", 1e3, "tissue thickness"),
    "thickness_variation": (
        "max",
        "%",
        1e2,
        "thickness variation within two thicknesses of a contact",
    ),
    "contacts": ("max", "", 1.0, "number of contacts"),
    "contact_force": ("max", "N", 1.0, "force of a contact"),
    "contact_area": ("range", "cm^2", 1e4, "area of a contact"),
    "contact_pressure": ("max", "kPa", 1e-3, "mean pressure of a contact"),
    "peak_pressure": ("max", "kPa", 1e-3, "highest pressure on a vertex"),
    "rim_distance": ("min", "mm", 1e3, "distance of a contact from the part's open rims"),
    "skin_area": ("range", "cm^2", 1e4, "skin area of the body's part (its size)"),
}
"""The axes: ``range`` axes are checked at both ends, ``max`` axes at the top only (a lighter or
more even load than the data's is no harder to answer), ``min`` axes at the bottom only (a
contact nearer the cut rims, where the tissue is held, than any in the data)."""

LOAD_AXES = ("thickness", "contact_force", "contact_pressure", "peak_pressure")
"""How hard the tissue is pushed: axes a test set widens an envelope along only with data of
its own intensity (never from the training box's averages)."""
SHAPE_AXES = ("contacts", "contact_area", "thickness_variation")
"""(``rim_distance`` is in neither: no test set widens it.)"""
"""How the load is laid out: the axes a test set on which a model kept its promise widens."""

PROMISE = {"rel_mee": 1.0, "peak_err": 5.0}
"""What a learned model promises inside its envelope on a test set: relative MEE <= 1 % and the
mean peak error within +-5 % (the targets of the tables)."""
SCENE_PROMISE = {"rel_mee": 1.5, "peak_err": 10.0}
"""What it promises for one scene inside its envelope: relative MEE <= 1.5 % and the peak within
+-10 %. A test set's mean keeps :data:`PROMISE`; single scenes scatter about it (the shipped
fine-arm models' peak errors have a standard deviation of 3-4 % on their test sets), so a scene's
bound is wider. The stability sweep's points (reports/stability_fine) hold the envelopes to it:
every point where a model breaks it, or the FEM fails, lies outside that model's envelope
(tests/test_stability.py)."""


def scene_promise() -> tuple[float, float]:
    """:data:`SCENE_PROMISE` as ``(relative MEE, peak error)``, both %."""
    return float(SCENE_PROMISE["rel_mee"]), float(SCENE_PROMISE["peak_err"])


def breaks_promise(rel_mee: float, peak_err: float, promise: dict | None = None) -> bool:
    """Whether one answer's relative MEE and signed peak error (both %) break ``promise``
    (default :data:`SCENE_PROMISE`).
    """
    promise = SCENE_PROMISE if promise is None else promise
    return bool(rel_mee > promise["rel_mee"] or abs(peak_err) > promise["peak_err"])


SLACK = 0.02
"""Relative allowance on every bound (2 %): loads rebuilt by another route round differently."""
VARIATION_ALLOWANCE = 0.02
"""Thickness variation near a contact (relative to its mean) tolerated beyond the data's: set by
the stability sweep (reports/stability): the shipped GNN, trained on uniform layers, stays under
1 % at 1.5 % variation and passes it at 3.8 %."""


def contacts(part: BodyPart, force: np.ndarray) -> list[np.ndarray]:
    """The contacts of a load: connected patches (over the mesh's edges) of the vertices with
    ``force > 0``, each a ``(K,)`` array of vertex indices; ``force`` ``(N,)``.
    """
    on = np.asarray(force) > 0
    loaded = np.flatnonzero(on)
    if len(loaded) == 0:
        return []
    e = part.edges
    e = np.searchsorted(loaded, e[on[e[:, 0]] & on[e[:, 1]]])  # edges inside the load, local
    label = np.arange(len(loaded))
    while True:  # each loaded vertex takes its patch's least index
        new = label.copy()
        np.minimum.at(new, e[:, 0], label[e[:, 1]])
        np.minimum.at(new, e[:, 1], label[e[:, 0]])
        new = new[new]  # jump along the chain
        if np.array_equal(new, label):
            break
        label = new
    return [loaded[label == c] for c in np.unique(label)]


def features(part: BodyPart, thickness: np.ndarray, force: np.ndarray) -> dict:
    """A scene's place on every axis of :data:`AXES` (SI units): scalars, and for the per-contact
    axes a list with one value per contact. ``thickness``, ``force`` ``(N,)`` m and N.
    """
    t = np.asarray(thickness, dtype=float)
    f = np.asarray(force, dtype=float)
    area = part.vertex_areas
    out = {
        "thickness": [float(t.min()), float(t.max())],
        "thickness_variation": 0.0,
        "contacts": 0,
        "contact_force": [],
        "contact_area": [],
        "contact_pressure": [],
        "peak_pressure": float((f / area).max(initial=0.0)),
        "skin_area": float(area.sum()),
    }
    found = contacts(part, f)
    for c in found:
        a = float(area[c].sum())
        out["contact_force"].append(float(f[c].sum()))
        out["contact_area"].append(a)
        out["contact_pressure"].append(float(f[c].sum()) / a)
        if out["thickness"][0] < out["thickness"][1]:  # else uniform: none
            tc = t[_around(part, c, 2.0 * float(t[c].max()))]
            out["thickness_variation"] = max(
                out["thickness_variation"], float((tc.max() - tc.min()) / tc.mean())
            )
    out["contacts"] = len(out["contact_force"])
    if part.rims:  # per contact: its vertex nearest an open rim
        out["rim_distance"] = [float(part.rim_distance[c].min()) for c in found]
    return out


def _around(part: BodyPart, vertices: np.ndarray, reach: float) -> np.ndarray:
    """The vertices within ``reach`` (m, straight line) of any of ``vertices``: the tissue a
    contact moves, whatever the mesh's resolution.
    """
    near = part.tree.query_ball_point(part.vertices[vertices], reach)
    return np.unique(np.concatenate([np.asarray(x, dtype=np.int64) for x in near]))


def _values(feat: dict, axis: str) -> list[float]:
    v = feat[axis]
    return [float(x) for x in v] if isinstance(v, list) else [float(v)]


@dataclass
class Envelope:
    """Named boxes over :data:`AXES`: ``{box: {axis: [lo, hi]}}`` in SI units, with the number
    of scenes each box was made from and where they came from.
    """

    boxes: dict = field(default_factory=dict)
    info: dict = field(default_factory=dict)  # {box: {"scenes": int, "source": str, ...}}
    limits: dict = field(default_factory=dict)
    """Bounds over every box, set where a model was measured to break its promise inside its
    data's support (the stability sweep): ``{axis: {"max": value, "source": str}}`` (SI)."""
    support: Support | None = None
    """The training scenes' joint support and the out-of-sample evidence of the predictor's
    errors (:mod:`stmpl.support`): a scene inside a box must also lie near scenes of the data
    and nearest a measured scene where the promise was kept. ``None`` in envelopes written
    before it (boxes and limits alone)."""

    def limit(self, axis: str, hi: float, source: str = "") -> None:
        """Cap ``axis`` (a ``max`` or ``range`` axis of :data:`AXES`) at ``hi`` (SI) for every
        box: a scene above it lies outside whatever box it fits.
        """
        if axis not in AXES or AXES[axis][0] == "min":
            raise ValueError(f"a limit needs a max or range axis of {sorted(AXES)}, got {axis!r}")
        if not np.isfinite(hi) or hi <= 0:
            raise ValueError(f"limit on {axis} must be finite and > 0, got {hi!r}")
        self.limits[axis] = {"max": float(hi), "source": source}

    @classmethod
    def of(
        cls, part, thickness, force, name: str = "training", source: str = "", body=None, **notes
    ) -> "Envelope":
        """The envelope of ``S`` scenes on ``part``: ``thickness``, ``force`` ``(S, N)`` (m, N)
        (on several bodies: see :meth:`add`).
        """
        env = cls()
        env.add(name, part, thickness, force, source=source, body=body, **notes)
        return env

    def add(self, name: str, part, thickness, force, source: str = "", body=None, **notes) -> None:
        """Add (or replace) box ``name``: the support of ``S`` scenes, ``(S, N)`` arrays, on
        ``part``, or on several bodies of one mesh: ``part`` a list of parts and ``body``
        ``(S,)`` the index of each scene's.
        """
        t = np.asarray(thickness, dtype=float)
        f = np.asarray(force, dtype=float)
        parts = list(part) if isinstance(part, (list, tuple)) else [part]
        body = np.zeros(len(t), int) if body is None else np.asarray(body, dtype=int)
        part = parts[0]
        if body.shape != (len(t),) or (len(body) and (body.min() < 0 or body.max() >= len(parts))):
            raise ValueError(
                f"body must give each of the {len(t)} scenes the index of its part "
                f"among {len(parts)}"
            )
        if t.ndim != 2 or t.shape != f.shape or t.shape[1] != part.n_vertices:
            raise ValueError(
                f"thickness and force must both be (S, {part.n_vertices}), got "
                f"{t.shape} and {f.shape}"
            )
        if len(t) == 0:
            raise ValueError(f"an envelope box ({name!r}) needs at least one scene")
        lo = {a: np.inf for a in AXES}
        hi = {a: -np.inf for a in AXES}
        coords = []
        for ts, fs, b in zip(t, f, body):
            feat = features(parts[b], ts, fs)
            coords.append(coordinates(feat))
            for a in AXES:
                vals = _values(feat, a)
                if vals:
                    lo[a], hi[a] = min(lo[a], min(vals)), max(hi[a], max(vals))
        self.boxes[name] = {a: [float(lo[a]), float(hi[a])] for a in AXES if np.isfinite(lo[a])}
        self.info[name] = {"scenes": int(len(t)), "source": source, **notes}
        if name == "training":
            self.support = Support.of(np.array(coords))

    def measure(
        self, part, thickness, force, rel_mee, peak_err, source: str = "", body=None
    ) -> np.ndarray:
        """Add out-of-sample evidence to the support: ``S`` scenes (``(S, N)`` arrays on
        ``part``, or several bodies as in :meth:`add`) and the predictor's relative MEE and
        signed peak error on each ``(S,)`` (%; NaN for a planned scene the FEM could not solve,
        where no answer is backed). Returns ``(S,)``: whether each kept
        :data:`SCENE_PROMISE`. Needs a ``training`` box (its support) first.
        """
        if self.support is None:
            raise ValueError("an envelope takes evidence only after its training box")
        t = np.asarray(thickness, dtype=float)
        f = np.asarray(force, dtype=float)
        parts = list(part) if isinstance(part, (list, tuple)) else [part]
        body = np.zeros(len(t), int) if body is None else np.asarray(body, dtype=int)
        rel = np.asarray(rel_mee, dtype=float)
        peak = np.asarray(peak_err, dtype=float)
        if not (len(t) == len(f) == len(body) == len(rel) == len(peak)) or len(t) == 0:
            raise ValueError(
                f"evidence needs one thickness, force, body, relative MEE and peak error per "
                f"scene, got {len(t)}, {len(f)}, {len(body)}, {len(rel)}, {len(peak)}"
            )
        coords = np.array(
            [coordinates(features(parts[b], ts, fs)) for ts, fs, b in zip(t, f, body)]
        )
        kept = np.array([not breaks_promise(r, p) for r, p in zip(rel, peak)])
        kept &= np.isfinite(rel) & np.isfinite(peak)
        self.support.measure(coords, kept, np.stack([rel, peak], 1), source, scene_promise())
        return kept

    def widen(
        self,
        name: str,
        part,
        thickness,
        force,
        base: str = "training",
        axes=SHAPE_AXES,
        source: str = "",
        body=None,
        **notes,
    ) -> np.ndarray:
        """Add box ``name``: box ``base`` widened along ``axes`` to cover those of ``S`` scenes
        (``(S, N)`` arrays) that fit ``base`` on every other axis; returns the ``(S,)`` mask
        of those scenes (measure a model on them before keeping the box: see
        :func:`stmpl.pipeline.zoo.measure`). Nothing is added when no scene qualifies. Several
        bodies:
        ``part`` a list and ``body`` ``(S,)`` indices, as in :meth:`add`.
        """
        t = np.asarray(thickness, dtype=float)
        f = np.asarray(force, dtype=float)
        parts = list(part) if isinstance(part, (list, tuple)) else [part]
        body = np.zeros(len(t), int) if body is None else np.asarray(body, dtype=int)
        box = {a: list(b) for a, b in self.boxes[base].items()}
        others = {a: b for a, b in box.items() if a not in axes}
        mask = np.zeros(len(t), dtype=bool)
        for k, (ts, fs) in enumerate(zip(t, f)):
            feat = features(parts[body[k]], ts, fs)
            if _outside(feat, others, base):
                continue
            mask[k] = True
            for a in axes:
                vals = _values(feat, a)
                if vals and a in box:
                    box[a] = [min(box[a][0], min(vals)), max(box[a][1], max(vals))]
        if mask.any():
            self.boxes[name] = box
            self.info[name] = {
                "scenes": int(mask.sum()),
                "source": source,
                "base": base,
                "widened": list(axes),
                **notes,
            }
        return mask

    def reasons(self, scene=None, *, part=None, thickness=None, force=None) -> list[str]:
        """Why a scene lies outside: ``[]`` when it fits a box and keeps every limit, else one
        sentence per limit it passes and per axis it leaves in the box it comes closest to fitting.
        Give a Scene or ``part, thickness, force``.
        """
        if scene is not None:
            part, thickness, force = scene.part, scene.thickness, scene.force
        if not self.boxes:
            return []
        feat = features(part, thickness, force)
        capped = [
            why
            for a, lim in self.limits.items()
            for why in _outside(
                feat,
                {a: [0.0, lim["max"]]},
                "",
                most=(
                    "where it was measured to stop keeping its promise: "
                    + (lim.get("source") or "a limit")
                ),
            )
        ]
        best = None
        for name, box in self.boxes.items():
            why = _outside(feat, box, name)
            if not why:
                best = []
                break
            if best is None or len(why) < len(best):
                best = why
        if not best and self.support is not None:  # inside a box: are the values seen together?
            best = self.support.reasons(coordinates(feat))
        return capped + best  # a cap first, then the data's own bounds the scene leaves

    def to_dict(self) -> dict:
        return {
            "format": FORMAT,
            "boxes": self.boxes,
            "info": self.info,
            **({"limits": self.limits} if self.limits else {}),
            **({"support": self.support.to_dict()} if self.support is not None else {}),
        }

    @classmethod
    def from_dict(cls, d: dict) -> "Envelope":
        """From :meth:`to_dict`'s output, checked; ``ValueError`` names what is wrong."""
        if not isinstance(d, dict) or d.get("format") != FORMAT:
            got = d.get("format") if isinstance(d, dict) else None
            raise ValueError(f"not a stmpl envelope (format {got!r})")
        boxes = d.get("boxes")
        if not isinstance(boxes, dict) or not boxes:
            raise ValueError("an envelope needs at least one box")
        for name, box in boxes.items():
            for a, b in box.items():
                if a not in AXES:
                    raise ValueError(f"envelope box {name!r} has an unknown axis {a!r}")
                if (
                    not isinstance(b, list)
                    or len(b) != 2
                    or not all(isinstance(x, (int, float)) and np.isfinite(x) for x in b)
                    or b[0] > b[1]
                ):
                    raise ValueError(
                        f"envelope box {name!r}, axis {a!r}: need [lo, hi] "
                        f"finite and rising, got {b!r}"
                    )
        env = cls(dict(boxes), dict(d.get("info") or {}))
        for a, lim in (d.get("limits") or {}).items():
            if not isinstance(lim, dict) or not isinstance(lim.get("max"), (int, float)):
                raise ValueError(f"envelope limit {a!r}: need {{max: value}}, got {lim!r}")
            env.limit(a, lim["max"], str(lim.get("source", "")))
        if d.get("support") is not None:
            env.support = Support.from_dict(d["support"])
        return env

    def summary(self, box: str = "training") -> str:
        """One line per axis of ``box`` in readable units (and one per limit)."""
        lines = []
        for a, lim in self.limits.items():
            kind, unit, k, what = AXES[a]
            lines.append(
                f"{what}: limited to {lim['max'] * k:.3g} {unit} ({lim.get('source') or 'a limit'})"
            )
        for a, (lo, hi) in self.boxes[box].items():
            kind, unit, k, what = AXES[a]
            rng = (
                f"{lo * k:.3g}-{hi * k:.3g}"
                if kind == "range"
                else f"from {lo * k:.3g}"
                if kind == "min"
                else f"up to {hi * k:.3g}"
            )
            lines.append(f"{what}: {rng} {unit}".rstrip())
        return "\n".join(lines)


def _outside(feat: dict, box: dict, name: str, most: str | None = None) -> list[str]:
    """Why ``feat`` leaves ``box`` (one sentence per axis; ``[]`` inside): each bound named as
    "the most (least) in ``name``", or an upper bound as ``most`` when given.
    """
    why = []
    for a, (kind, unit, k, what) in AXES.items():
        if a not in box:
            continue
        vals = _values(feat, a)
        if not vals:
            continue
        lo, hi = box[a]
        top = hi * (1 + SLACK) + (VARIATION_ALLOWANCE if a == "thickness_variation" else 0.0)
        if kind == "min":
            if min(vals) < lo * (1 - SLACK):
                why.append(
                    f"{what} {min(vals) * k:.3g} {unit} < {lo * k:.3g} {unit} (the least in {name})"
                )
            continue
        if max(vals) > top:
            why.append(
                f"{what} {max(vals) * k:.3g} {unit} > {hi * k:.3g} {unit} "
                f"({most or f'the most in {name}'})".replace("  ", " ")
            )
        elif kind == "range" and min(vals) < lo * (1 - SLACK):
            why.append(
                f"{what} {min(vals) * k:.3g} {unit} < {lo * k:.3g} {unit} "
                f"(the least in {name})".replace("  ", " ")
            )
    return why
