"""What a dataset config asks to solve: load placements on the part (spread evenly, built once
and checked before any solving), their split (train / val / test by placement) and the tasks
(one placement at one thickness, solved by continuation over the force levels).
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass

import numpy as np
import trimesh

import stmpl.contact.pressing as contact
from fem.shapes import PRESSES
from stmpl import loads
from stmpl.body.spec import part_from_spec
from stmpl.contact.hand import Hand, grasp, palm_press
from stmpl.contact.posing import signed_distance
from stmpl.part import BodyPart

CENTRED = ("press_disk", "press_sphere")
"""The presses placed at a vertex (their centres spread over the part, clear of its rims)."""


def farthest_points(part: BodyPart, count: int, clearance: float = 0.0) -> np.ndarray:
    """``count`` vertex indices spread evenly over the part (farthest-point sampling from the
    vertex nearest the centroid; deterministic), each at least ``clearance`` (m) from the
    part's cut rims (which the FEM holds in place).
    """
    x = part.vertices
    among = np.arange(part.n_vertices)
    if clearance > 0 and part.rims:
        rim = x[np.concatenate(part.rims)]
        far = np.linalg.norm(x[:, None] - rim[None], axis=2).min(1) >= clearance
        among = np.flatnonzero(far)
    if count > len(among):
        raise ValueError(
            f"{count} centres asked for on {part.name}, which has only {len(among)} vertices "
            f"{1e3 * clearance:.0f} mm or more from its cut rims (each centre is a distinct vertex)"
        )
    x = x[among]
    first = int(np.argmin(np.linalg.norm(x - x.mean(0), axis=1)))
    out, d = [first], np.linalg.norm(x - x[first], axis=1)
    for _ in range(count - 1):
        nxt = int(np.argmax(d))
        out.append(nxt)
        d = np.minimum(d, np.linalg.norm(x - x[nxt], axis=1))
    return among[np.array(out[:count])]


def press_clearance(spec: dict, thickness_mm) -> float:
    """How far (m) a pressed object's centre keeps from the part's cut rims: its largest radius
    plus twice the deepest tissue. The FEM holds the rims in place, so an object over them would
    press skin that cannot give way, and the held cut stiffens the tissue about as far as the
    tissue is deep.
    """
    return max(float(r) for r in spec.get("radii", [0.01])) + 2e-3 * max(thickness_mm)


def placements(cfg: dict, part: BodyPart) -> list[dict]:
    """Every load placement of the config as ``{"kind", "params"}`` (params for the
    :mod:`stmpl.loads` primitive, total force left out), kinds in alphabetical order.
    """
    out = []
    for kind in sorted(cfg["placements"]):  # canonical order: a YAML round trip keeps task ids
        spec = cfg["placements"][kind]
        if kind in ("disk", "ellipse", "spots", *CENTRED):
            away = press_clearance(spec, cfg["thickness_mm"]) if kind in CENTRED else 0.0
            spread = farthest_points(part, int(spec.get("centres", 8)), away)
            centres = [int(v) for v in spread[int(spec.get("skip", 0)) :]]
        if kind == "disk":
            out += [
                {"kind": kind, "params": {"at": c, "radius": float(r)}}
                for c in centres
                for r in spec.get("radii", [0.02])
            ]
        elif kind == "press_grip":
            out += [
                {"kind": kind, "params": {"along": float(a), "around": float(r), "grip": str(g)}}
                for a in spec.get("along", [0.5])
                for r in spec.get("around", [0.0])
                for g in spec.get("grips", ["whole"])
            ]
        elif kind in CENTRED:
            rounding = {}
            if kind == "press_disk":
                rounding = {"rounding": float(spec.get("rounding", 0.0))}
            out += [
                {"kind": kind, "params": {"at": c, "radius": float(r), **rounding}}
                for c in centres
                for r in spec.get("radii", [0.01])
            ]
        elif kind == "ellipse":
            out += [
                {
                    "kind": kind,
                    "params": {"at": c, "semi_axes": [float(a), float(b)], "angle": float(t)},
                }
                for c in centres
                for a, b in spec.get("semi_axes", [[0.03, 0.015]])
                for t in spec.get("angles", [0.0])
            ]
        elif kind == "seam_disk":
            out += [
                {"kind": kind, "params": {"at": float(a), "radius": float(r)}}
                for a in spec.get("at", [0.5])
                for r in spec.get("radii", [0.02])
            ]
        elif kind == "spots":
            out += [
                {
                    "kind": kind,
                    "params": {
                        "at": c,
                        "count": int(k),
                        "radius": float(r),
                        "spread": float(spec.get("spread", 0.04)),
                    },
                }
                for c in centres
                for k in spec.get("counts", [3])
                for r in spec.get("radii", [0.008])
            ]
        elif kind == "band":
            out += [
                {"kind": kind, "params": {"at": float(a), "width": float(w)}}
                for a in spec.get("at", [0.5])
                for w in spec.get("widths", [0.03])
            ]
        elif kind == "grasp":
            out += [
                {
                    "kind": kind,
                    "params": {
                        "along": float(a),
                        "around": float(r),
                        "grip": str(g),
                        "hand_height": float(h),
                        "depth": float(spec.get("depth", 0.002)),
                    },
                }
                for a in spec.get("along", [0.7])
                for r in spec.get("around", [0.0])
                for g in spec.get("grips", ["whole"])
                for h in spec.get("hand_heights", [0.5])
            ]
        elif kind == "palm":
            out += [
                {
                    "kind": kind,
                    "params": {
                        "uv": [float(u), float(v)],
                        "spin": float(s),
                        "hand_height": float(h),
                        "depth": float(spec.get("depth", 0.002)),
                    },
                }
                for u, v in spec.get("uv", [[0.5, 0.5]])
                for s in spec.get("spins", [0.0])
                for h in spec.get("hand_heights", [0.5])
            ]
        elif kind == "letter":
            out += [
                {
                    "kind": kind,
                    "params": {
                        "char": str(c),
                        "uv": [float(u), float(v)],
                        "height": float(h),
                        "stroke": float(s),
                        "angle": float(t),
                    },
                }
                for c in spec.get("chars", ["A"])
                for u, v in spec.get("uv", [[0.5, 0.5]])
                for h in spec.get("heights", [0.08])
                for s in spec.get("strokes", [0.01])
                for t in spec.get("angles", [0.0])
            ]
    return out


def make_load(part: BodyPart, placement: dict, total: float = 1.0):
    """The :class:`~stmpl.loads.Load` of a placement (of a press, the object's footprint: the
    disk of its radius where it first touches); names the placement if it is impossible.
    """
    params = dict(placement["params"])
    if placement["kind"] in HANDS:  # the touched vertices were found by plan()
        return loads.from_vertices(part, placement["touched"], total, placement["kind"], params)
    if placement["kind"] in PRESSES:  # the object's footprint: where it presses at first
        params.pop("rounding", None)
        params["at"] = int(params["at"])
        return loads.disk(part, total=total, **params)
    if "uv" in params:
        params["uv"] = tuple(params["uv"])
    try:
        return loads.PRIMITIVES[placement["kind"]](part, total=total, **params)
    except (ValueError, IndexError) as e:
        raise ValueError(
            f"impossible load placement {placement['kind']} {json.dumps(placement['params'])}: {e}"
        ) from e


def split_of(n_placements: int, shares, seed: int) -> np.ndarray:
    """``(P,)`` split index (0 train, 1 val, 2 test) per placement, shuffled with ``seed``."""
    order = np.random.default_rng(seed).permutation(n_placements)

    def count(share):  # every split with a share gets a placement once there are three
        n = int(round(share * n_placements))
        return max(n, 1) if share > 0 and n_placements >= 3 else n

    n_val, n_test = count(shares[1]), count(shares[2])
    n_train = n_placements - n_val - n_test
    out = np.empty(n_placements, dtype=np.int8)
    out[order[:n_train]] = 0
    out[order[n_train : n_train + n_val]] = 1
    out[order[n_train + n_val :]] = 2
    return out


@dataclass(frozen=True)
class Plan:
    """All tasks of a config: ``tasks[i] = (placement index, thickness index)``."""

    cfg: dict
    part: BodyPart
    placements: list
    split: np.ndarray
    tasks: list
    skipped: list = ()
    """Placements left out before solving (grasps that touch no vertex), with the reason."""

    @property
    def n_shards(self) -> int:
        return -(-len(self.tasks) // self.cfg["shard_tasks"])

    def shard_tasks(self, k: int) -> list[int]:
        n = self.cfg["shard_tasks"]
        return list(range(k * n, min((k + 1) * n, len(self.tasks))))


def plan(cfg: dict, part: BodyPart | None = None) -> Plan:
    """Expand a config into tasks; every placement is built once here so a bad one fails now,
    before any solving.
    """
    part = part if part is not None else part_from_spec(cfg["body"], cfg["part"])
    pls, skipped, hands = [], [], {}
    for p in placements(cfg, part):
        if p["kind"] in HANDS:
            try:
                p["touched"] = HANDS[p["kind"]](part, p["params"], hands)
            except ValueError as e:  # a hand that reaches no vertex: counted
                skipped.append({**p, "reason": str(e).split(":")[0]})
                continue
        ld = make_load(part, p)
        p["vertices"], p["area"] = int(ld.count), float(ld.area)
        pls.append(p)
    if not pls:
        raise ValueError(
            f"no placement of the config touches the part ({len(skipped)} grasps found no contact)"
        )
    split = split_of(len(pls), cfg["splits"], cfg["seed"])
    levels = len(cfg["thickness_mm"])
    if cfg.get("thickness_cycle"):  # each placement at one level, in turn
        tasks = [(i, i % levels) for i in range(len(pls))]
    else:
        tasks = [(i, j) for i in range(len(pls)) for j in range(levels)]
    return Plan(cfg, part, pls, split, tasks, skipped)


def grasp_contact(part: BodyPart, params: dict, hands: dict) -> list[int]:
    """The vertices anny's right hand touches in the grasp ``params`` describe (hands of each
    size are built once, in ``hands``); ``ValueError`` when it touches none.
    """
    h = params["hand_height"]
    if h not in hands:
        hands[h] = Hand(phenotype={"height": h})
    g = grasp(part, hands[h], params["along"], params["around"], params["grip"], params["depth"])
    return [int(v) for v in contact.contact(part, g.pressing(1.0)).vertices]


def palm_contact(part: BodyPart, params: dict, hands: dict) -> list[int]:
    """The vertices anny's open right hand touches, laid on the skin at chart point ``params["uv"]``
    (:func:`stmpl.contact.hand.palm_press`, the fingers turned by ``spin`` rad from the chart's
    ``x``, as ``stmpl simulate`` lays it on a part that is not a limb); ``ValueError`` when it
    touches none or lies past the part's rim.
    """
    h = params["hand_height"]
    if h not in hands:
        hands[h] = Hand(phenotype={"height": h})
    p = palm_press(
        part, hands[h], tuple(params["uv"]), params["depth"], math.pi / 2 + params["spin"], 1.0
    )
    return [int(v) for v in contact.contact(part, p).vertices]


def grip_contact(part: BodyPart, params: dict, hands: dict) -> list[int]:
    """The footprint of anny's right hand closing in a grip (a ``press_grip``): the vertices
    within 5 mm of the grip set 2 mm deep (its fingers may press between the vertices of a
    coarse part); ``ValueError`` when none is.
    """
    if "grip" not in hands:
        hands["grip"] = Hand(side="R")
    g = grasp(part, hands["grip"], params["along"], params["around"], params["grip"], 0.002)
    mesh = trimesh.Trimesh(g.vertices, g.faces, process=False)
    near = np.flatnonzero(signed_distance(mesh, part.vertices) < 0.005)
    if not len(near):
        raise ValueError("no contact: the grip comes within 5 mm of no vertex")
    return [int(v) for v in near]


HANDS = {
    "grasp": lambda part, params, hands: grasp_contact(part, params, hands),
    "palm": lambda part, params, hands: palm_contact(part, params, hands),
    "press_grip": lambda part, params, hands: grip_contact(part, params, hands),
}
"""Placement kinds whose load is the skin anny's hand touches, found once in :func:`plan`
(looked up at call time, so a test can stand in for the hand)."""
