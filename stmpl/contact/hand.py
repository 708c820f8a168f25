"""Hand grasps with anny's own hand: a right hand set around a limb, its fingers curled until
they reach the skin.

:class:`Hand` poses anny's articulated hand (the finger bones ``finger1..5-1..3`` of its rig, one
curl per finger: every joint of the finger flexes by ``curl x`` :data:`JOINT_ANGLE`) and cuts the
hand's mesh out of the posed body. :func:`grasp` places it: the palm's centre over the skin at a
fraction ``along`` the limb and an angle ``around`` it (from the body's front, right-handed about
the limb axis), the palm facing the limb, the fingers across it; then the hand is moved along the
normal until the palm presses ``depth`` into the skin (``whole``) or clears it (the other grips),
and each finger of the grip is curled, by bisection, until it presses ``depth`` into the skin.
Grips: ``whole`` (palm and five fingers), ``tripod`` (thumb and two fingers), ``pinch`` (thumb
and index); fingers outside the grip close into a fist. The result is a mesh in the limb's body
coordinates (:class:`Grasp`), pressed through :mod:`stmpl.contact.pressing` like any object.

Depths are measured against the limb's skin by a signed distance to a dense sampling of its
surface (a point's distance to the nearest sample along that sample's outward normal).
"""

from __future__ import annotations

import hashlib
import json
import pathlib
from dataclasses import dataclass, field
from importlib.metadata import version

import numpy as np
from scipy.spatial import cKDTree

from stmpl.body.anny_body import AnnyBody
from stmpl.body.model import default_cache_dir
from stmpl.contact.grips import GRIPS
from stmpl.contact.objects import surface_frame
from stmpl.contact.pressing import Pressing, rotation_matrix
from stmpl.files import atomic_savez
from stmpl.mesh import Mesh
from stmpl.part import BodyPart

FINGERS = {"thumb": 1, "index": 2, "middle": 3, "ring": 4, "little": 5}
JOINT_ANGLE = np.deg2rad(85.0)
"""rad: how far each finger joint flexes at curl 1 (three joints: a closed fist)."""
CURL_RANGE = (-0.6, 1.1)
OPEN_CURL = -0.3
"""The open hand of :func:`palm_press`: every finger stretched a little past rest (anny's rest
hand is half curled; laid on a belly, its knuckles would touch first)."""
PALM_CLEARANCE = 0.015
"""m: how far off the skin the palm stays in a grip that holds with the fingers alone."""


class Hand:
    """anny's right (``side="R"``) or left hand, of a body with the given ``phenotype`` (hand
    size follows height, gender, proportions, ...), posed by one curl per finger.
    """

    def __init__(self, phenotype: dict | None = None, side: str = "R"):
        import torch  # deferred: about a second to import; the core's types do not need it

        if side not in ("R", "L"):
            raise ValueError(f"side must be 'R' or 'L', got {side!r}")
        self.side, self.body = side, AnnyBody(phenotype=phenotype or {})
        m = self.body.anny
        self._labels = list(m.bone_labels)
        self._phenotype = {k: float(v) for k, v in self.body.phenotype.items()}
        with torch.no_grad():
            out = m(phenotype_kwargs=self._phenotype)
        self._dtype = out["vertices"].dtype
        w, bi = m.vertex_bone_weights.numpy(), m.vertex_bone_indices.numpy()
        dominant = np.array(self._labels)[bi[np.arange(len(bi)), w.argmax(axis=1)]]
        hand_bones = [
            b
            for b in self._labels
            if b.endswith("." + side)
            and (b.startswith(("finger", "metacarpal")) or b.startswith("wrist"))
        ]
        keep = np.isin(dominant, hand_bones)
        faces = m.faces.numpy().astype(np.int64)
        faces = faces[keep[faces].all(1)]
        self.vertex_ids = np.unique(faces)  # body vertex indices
        remap = -np.ones(len(keep), dtype=np.int64)
        remap[self.vertex_ids] = np.arange(len(self.vertex_ids))
        self.faces = remap[faces]
        d = dominant[self.vertex_ids]
        self.finger_of = {
            f: np.flatnonzero(np.char.startswith(d.astype(str), f"finger{k}-"))
            for f, k in FINGERS.items()
        }
        self.palm = np.flatnonzero(np.char.startswith(d.astype(str), "metacarpal"))
        self.rest = out["vertices"][0].numpy()[self.vertex_ids]
        poses = out["bone_poses"][0].numpy()
        self._head = {b: poses[self._labels.index(b)][:3, 3] for b in hand_bones}
        self._axes = self._curl_axes()

    def _bone(self, name: str) -> np.ndarray:
        return self._head[f"{name}.{self.side}"]

    def frame(self, vertices: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
        """``(centre (3,), R (3, 3))`` of the palm at rest: ``R``'s columns are the finger
        direction, the palm normal (out of the palm) and their cross product.
        """
        # anny's metacarpal k carries finger k + 1 (the thumb hangs from the wrist)
        c = np.mean(
            [self._bone(f"finger{k}-1") for k in (2, 3, 4, 5)]
            + [self._bone(f"metacarpal{k}") for k in (1, 2, 3, 4)],
            axis=0,
        )
        f = self._bone("finger3-1") - self._bone("metacarpal2")
        f /= np.linalg.norm(f)
        across = self._bone("finger2-1") - self._bone("finger5-1")  # little -> index
        n = np.cross(across, f) if self.side == "R" else np.cross(f, across)
        n -= f * (n @ f)
        n /= np.linalg.norm(n)
        return c, np.stack([f, n, np.cross(f, n)], 1)

    def _curl_axes(self) -> dict:
        """Per finger, the world axis whose positive rotation flexes it towards the palm."""
        _, R = self.frame()
        n = R[:, 1]
        out = {}
        for name, k in FINGERS.items():
            d = self._bone(f"finger{k}-3") - self._bone(f"finger{k}-1")
            axis = np.cross(d, n)
            out[name] = axis / np.linalg.norm(axis)
        return out

    def vertices(self, curls: dict) -> np.ndarray:
        """``(V, 3)`` hand vertices (body coordinates, m) with each finger at its curl (0 as
        at rest, 1 a closed fist); fingers not named stay at rest.
        """
        import torch  # deferred: about a second to import; the core's types do not need it

        pose = {}
        for name, c in curls.items():
            if name not in FINGERS:
                raise ValueError(f"unknown finger {name!r}; fingers: {list(FINGERS)}")
            c = float(c)
            if not CURL_RANGE[0] <= c <= CURL_RANGE[1]:
                raise ValueError(f"curl of {name} must lie in {CURL_RANGE}, got {c}")
            M = np.eye(4)
            M[:3, :3] = rotation_matrix(self._axes[name], c * JOINT_ANGLE)
            for j in (1, 2, 3):
                pose[f"finger{FINGERS[name]}-{j}.{self.side}"] = torch.tensor(M, dtype=self._dtype)[
                    None
                ]
        with torch.no_grad():
            out = self.body.anny(pose_parameters=pose or None, phenotype_kwargs=self._phenotype)
        return out["vertices"][0].numpy()[self.vertex_ids]


@dataclass(frozen=True, eq=False)
class Grasp:
    """A posed hand around a limb: ``vertices`` ``(V, 3)`` and ``faces`` in the limb's body
    coordinates, the ``curls`` found, the ``grip`` and where it holds; ``reached`` names the
    fingers that press ``depth`` into the skin (a finger that could not reach is left out).
    """

    vertices: np.ndarray
    faces: np.ndarray
    curls: dict
    grip: str
    along: float
    around: float
    depth: float
    reached: tuple = field(default=())

    def mesh(self):
        import trimesh  # deferred: object meshes and closest points only

        return trimesh.Trimesh(self.vertices, self.faces, process=False)

    def pressing(self, total: float, name: str = "hand") -> Pressing:
        """The hand, already posed, as a :class:`~stmpl.contact.pressing.Pressing` of ``total``
        N (its mesh a :class:`stmpl.mesh.Mesh`: no trimesh to import).
        """
        return Pressing(Mesh(self.vertices, self.faces), np.eye(4), total, name)


GRASP_CACHE = 1
"""The version of :func:`grasp`'s answers kept on disk (:func:`cached_grasp`); a change to what
``grasp`` returns raises it, and older files are then not read."""


def kept_file(folder: str, part: BodyPart, placement: list) -> pathlib.Path:
    """Where a hand posed on ``part`` at ``placement`` (its version, the hand and where it is:
    plain JSON) is kept: ``$STMPL_CACHE_DIR/<folder>/``, named by the part's mesh, the
    placement and anny's version.
    """
    key = hashlib.sha256()
    key.update(np.ascontiguousarray(part.vertices, dtype=np.float64).tobytes())
    key.update(np.ascontiguousarray(part.faces, dtype=np.int64).tobytes())
    key.update(json.dumps([version("anny"), placement], sort_keys=True).encode())
    return default_cache_dir() / folder / f"{key.hexdigest()[:24]}.npz"


def cached_grasp(
    part: BodyPart,
    phenotype: dict | None = None,
    along: float = 0.5,
    around: float = 0.0,
    grip: str = "whole",
    depth: float = 0.002,
    side: str = "R",
) -> Grasp:
    """:func:`grasp` of the ``side`` hand of the anny body of ``phenotype``, kept on disk
    (``$STMPL_CACHE_DIR/grasps``) under the part's mesh, the hand and the placement: a grasp
    made before is read back without running anny at all (posing a hand takes about fifty of
    its forward passes).
    """
    if grip not in GRIPS:
        raise ValueError(f"grip must be one of {sorted(GRIPS)}, got {grip!r}")
    placement = [phenotype or {}, side, float(along), float(around), grip, float(depth)]
    f = kept_file("grasps", part, [GRASP_CACHE, placement])
    if f.is_file():
        with np.load(f) as z:
            curls = dict(zip(FINGERS, z["curls"].tolist()))
            reached = tuple(str(r) for r in z["reached"])
            return Grasp(z["vertices"], z["faces"], curls, grip, along, around, depth, reached)
    g = grasp(part, Hand(phenotype=phenotype, side=side), along, around, grip, depth)
    arrays = {
        "vertices": np.asarray(g.vertices, dtype=np.float64),
        "faces": np.asarray(g.faces, dtype=np.int64),
        "curls": np.array([g.curls[k] for k in FINGERS], dtype=np.float64),
        "reached": np.array(g.reached, dtype=str),
    }
    atomic_savez(f, arrays)
    return g


def palm_press(
    part: BodyPart,
    hand: Hand,
    uv=(0.5, 0.5),
    depth: float = 0.002,
    spin: float = 0.0,
    total: float = 0.4,
    name: str = "right hand (palm)",
    steps: int = 6,
) -> Pressing:
    """The open hand laid on the skin at chart point ``uv``, palm towards it, fingers stretched
    (:data:`OPEN_CURL`) along the surface's ``x`` turned by ``spin`` rad
    (:func:`stmpl.contact.objects.surface_frame`), and lowered along the normal until its deepest
    point lies ``depth`` m inside the skin: a :class:`~stmpl.contact.pressing.Pressing` of ``total``
    N for a part that is not a limb (a belly), where :func:`grasp` has nothing to close around.
    """
    if not (np.isfinite(depth) and 0 < depth < 0.01):
        raise ValueError(f"depth must lie in (0, 10) mm, got {depth * 1e3:g} mm")
    x = hand.vertices({f: OPEN_CURL for f in FINGERS})
    c, R = hand.frame()
    f, n = R[:, 0], R[:, 1]  # finger direction, out of the palm
    z = -n  # the palm faces the object's -z
    mesh = Mesh((x - c) @ np.stack([f, np.cross(z, f), z], 1), hand.faces)
    pose = surface_frame(part, uv=uv, spin=spin)
    normal = pose[:3, 2].copy()
    pose[:3, 3] -= float(mesh.vertices[:, 2].min()) * normal  # palm-most point on the skin
    skin = SkinDistance(part)
    for _ in range(steps):  # a rigid shift along the normal: the deepest point to depth
        s, over = skin.over(mesh.vertices @ pose[:3, :3].T + pose[:3, 3])
        if not over.any():
            raise ValueError(f"the hand at {tuple(uv)} lies past the rim of {part.name!r}")
        gap = float(s[over].min()) + depth  # points past the part's rim do not count
        pose[:3, 3] -= gap * normal
        if abs(gap) < 0.02 * depth:
            break
    return Pressing(mesh, pose, total, name)


class SkinDistance:
    """Signed distance (m, positive outside) to a part's skin, from a dense sampling of its
    surface with normals (about ``spacing`` m apart).
    """

    def __init__(self, part: BodyPart, spacing: float = 0.0015):

        v, f = part.vertices, part.faces
        tri = v[f]
        area = 0.5 * np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1)
        counts = np.maximum(1, np.ceil(area / spacing**2)).astype(int)
        rng = np.random.default_rng(0)
        face = np.repeat(np.arange(len(f)), counts)
        r1, r2 = rng.random(len(face)), rng.random(len(face))
        s = np.sqrt(r1)
        bary = np.stack([1 - s, s * (1 - r2), s * r2], 1)
        self.points = np.einsum("kj,kjd->kd", bary, tri[face])
        nrm = np.einsum("kj,kjd->kd", bary, part.normals[f[face]])
        self.normals = nrm / np.linalg.norm(nrm, axis=1, keepdims=True)
        self.tree = cKDTree(self.points)

    def __call__(self, x: np.ndarray) -> np.ndarray:
        _, i = self.tree.query(x)
        return np.einsum("ij,ij->i", x - self.points[i], self.normals[i])

    def over(self, x: np.ndarray, reach: float = 0.003) -> tuple[np.ndarray, np.ndarray]:
        """``(signed distance (P,), over (P,) bool)``: whether each point lies over (or under)
        the skin, within ``reach`` m of its nearest sample sideways, not past the part's rim.
        """
        d, i = self.tree.query(x)
        s = np.einsum("ij,ij->i", x - self.points[i], self.normals[i])
        return s, np.sqrt(np.maximum(d**2 - s**2, 0.0)) < reach


def front_across(axis: np.ndarray) -> np.ndarray:
    """The unit direction across a limb of ``axis`` ``(3,)`` that faces the body's front (anny
    faces -y): where the angle ``around`` the limb counts from.
    """
    front = np.array([0.0, -1.0, 0.0])
    ref = front - axis * (front @ axis)
    return ref / np.linalg.norm(ref)


def limb_point(part: BodyPart, along: float, around: float) -> tuple:
    """``(skin point, outward direction, limb axis direction)`` at fraction ``along`` the limb
    and angle ``around`` (rad, from the body's front, right-handed about the axis).
    """
    if part.axis is None:
        raise ValueError(f"part {part.name!r} has no limb axis: a hand grasps a limb")
    if not np.isfinite(around):
        raise ValueError(f"around must be finite, got {around}")
    centre, z, s0 = part.limb_frame(along)
    s = part.axial
    ref = front_across(z)
    d = np.cos(around) * ref + np.sin(around) * np.cross(z, ref)
    off = part.vertices - centre
    radial = off - np.outer(off @ z, z)
    near = (np.abs(s - s0) < 0.015) & (radial @ d > 0.9 * np.linalg.norm(radial, axis=1))
    if not near.any():
        raise ValueError(f"no skin at along {along}, around {around} rad on {part.name!r}")
    r = float(np.median(np.linalg.norm(radial[near], axis=1)))
    return centre + r * d, d, z


def grasp(
    part: BodyPart,
    hand: Hand,
    along: float = 0.5,
    around: float = 0.0,
    grip: str = "whole",
    depth: float = 0.002,
    steps: int = 8,
) -> Grasp:
    """Set ``hand`` around the limb ``part`` and curl the grip's fingers until each presses
    ``depth`` m into the skin (see the module docstring).
    """
    if grip not in GRIPS:
        raise ValueError(f"grip must be one of {sorted(GRIPS)}, got {grip!r}")
    if not (np.isfinite(depth) and 0 < depth < 0.01):
        raise ValueError(f"depth must lie in (0, 10) mm, got {depth * 1e3:g} mm")
    skin = SkinDistance(part)
    point, d, z = limb_point(part, along, around)
    c, R = hand.frame()
    t = np.cross(z, d)  # fingers wrap around the limb
    target = np.stack([t, -d, np.cross(t, -d)], 1)  # finger dir, palm normal, ...
    rot = target @ R.T
    active = GRIPS[grip]
    closed = {f: (0.0 if f in active else 1.0) for f in FINGERS}

    def placed(curls):
        return (hand.vertices(curls) - c) @ rot.T + point

    def depth_of(x, f):
        return float(-skin(x[hand.finger_of[f]]).min())

    # Rounds: set the palm (pressed depth deep for a whole-hand grip, else held at least
    # PALM_CLEARANCE off the skin) for the current curls; curl the grip's fingers by bisection
    # (all at once: they move independently); a finger already too deep when stretched lifts
    # the hand (not for a whole-hand grip, whose palm is pressed), and the knuckles, which move
    # with the curls, are set again.
    curls = dict(closed)
    for _ in range(4):
        palm = float(skin(placed(curls)[hand.palm]).min())
        lift = -depth - palm if grip == "whole" else max(0.0, PALM_CLEARANCE - palm)
        point = point + d * lift
        # a finger closes until it first presses depth deep (it could sweep on through the
        # limb): a coarse sweep brackets that first contact, bisection refines it
        grid = np.linspace(*CURL_RANGE, 14)
        lo = {f: grid[0] for f in active}
        hi = {f: grid[-1] for f in active}
        found: set = set()
        for a, b in zip(grid[:-1], grid[1:]):
            x = placed({**curls, **{f: b for f in active}})
            for f in set(active) - found:
                if depth_of(x, f) >= depth:
                    lo[f], hi[f] = a, b
                    found.add(f)
        for _ in range(steps):
            mid = {f: 0.5 * (lo[f] + hi[f]) for f in active}
            x = placed({**curls, **mid})
            for f in active:
                if depth_of(x, f) < depth:  # not deep enough: curl more
                    lo[f] = mid[f]
                else:
                    hi[f] = mid[f]
        curls.update({f: 0.5 * (lo[f] + hi[f]) for f in active})
        x = placed(curls)
        stretched = placed({**curls, **{f: CURL_RANGE[0] for f in active}})
        excess = max(depth_of(stretched, f) - depth for f in active)
        palm = float(skin(x[hand.palm]).min())
        if grip != "whole" and excess > 1e-4:
            point = point + d * excess
            continue
        if grip != "whole" or abs(-palm - depth) < 0.1 * depth:
            break
    reached = tuple(f for f in active if abs(depth_of(x, f) - depth) < 0.25 * depth)
    return Grasp(x, hand.faces, curls, grip, float(along), float(around), float(depth), reached)
