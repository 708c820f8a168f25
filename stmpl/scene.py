"""What a predictor takes and gives: a :class:`Scene` (a part, its tissue thickness, and either
the external normal force or the pose of the objects pressing on it) and a
:class:`Deformation` (a displacement per vertex; for a posed scene also the contact force on
each vertex and the objects' reaction).

Both are frozen and validated on construction; errors name the field and the bad value. Both save
to one ``.npz`` (arrays, the part included, so a file is self-contained) with a JSON header.
"""

from __future__ import annotations

import json
import pathlib
from dataclasses import dataclass, field

import numpy as np

from stmpl import tissue
from stmpl.files import atomic_savez
from stmpl.loads import FORCE_RANGE, Load
from stmpl.part import BodyPart
from stmpl.pose import Pose

FORMAT = "stmpl-scene/1"


@dataclass(frozen=True, eq=False)
class Scene:
    """A body part under load: given by the force on the skin, or by where objects are.

    Attributes:
        part: the body part (rest pose).
        thickness: ``(N,)`` soft-tissue thickness per vertex, m, in ``tissue.THICKNESS_RANGE``.
        force: ``(N,)`` normal force per vertex, N, >= 0, pushing along ``-part.normals``;
            ``None`` when the scene gives a ``pose`` instead (the force is then what is asked).
        load: the load that made ``force`` (optional, for reports).
        meta: free JSON-serialisable notes (e.g. phenotype, placement id).
        pose: the objects at their pose (:class:`~stmpl.pose.Pose`), for a scene given by
            where the objects are; ``None`` for a scene given by its force.
    """

    part: BodyPart
    thickness: np.ndarray
    force: np.ndarray | None = None
    load: Load | None = None
    meta: dict = field(default_factory=dict)
    pose: Pose | None = None

    def __post_init__(self) -> None:
        t = tissue.check(self.part, self.thickness)
        n = self.part.n_vertices
        if self.pose is not None:
            self._check_pose(t)
            return
        if self.force is None:
            raise ValueError("a Scene needs a force per vertex or an object's pose")
        f = np.asarray(self.force, dtype=float)
        if f.shape != (n,):
            raise ValueError(
                f"Scene.force must have shape ({n},) for part {self.part.name!r}, got {f.shape}"
            )
        if not np.isfinite(f).all():
            i = int(np.argmax(~np.isfinite(f)))
            raise ValueError(f"Scene.force is not finite at vertex {i} (value {f[i]})")
        if (f < 0).any():
            i = int(np.argmin(f))
            raise ValueError(
                f"Scene.force must be >= 0 N (it pushes inward); vertex {i} has {f[i]:g} N"
            )
        if f.max(initial=0.0) > FORCE_RANGE[1]:
            i = int(np.argmax(f))
            raise ValueError(
                f"Scene.force must be <= {FORCE_RANGE[1]:g} N per vertex (the "
                f"normalisation range); vertex {i} has {f[i]:g} N"
            )
        if self.load is not None:
            if not isinstance(self.load, Load):
                raise TypeError(f"Scene.load must be a Load, got {type(self.load).__name__}")
            if self.load.part_id and self.load.part_id != self.part.fingerprint:
                raise ValueError(
                    f"the {self.load.kind} load was built on another part than "
                    f"the scene's {self.part.name!r} ({n} vertices): build it on "
                    "the scene's part"
                )
        t.setflags(write=False)
        f = f.copy()
        f.setflags(write=False)
        object.__setattr__(self, "thickness", t)
        object.__setattr__(self, "force", f)

    def _check_pose(self, thickness: np.ndarray) -> None:
        if self.force is not None or self.load is not None:
            raise ValueError(
                "a Scene gives a force or an object's pose, not both: the force on a posed "
                "object is what a predictor answers"
            )
        if not isinstance(self.pose, Pose):
            raise TypeError(f"Scene.pose must be a Pose, got {type(self.pose).__name__}")
        n = self.part.n_vertices
        if self.pose.gap.shape != (n,):
            raise ValueError(
                f"Scene.pose.gap must have shape ({n},) for part {self.part.name!r}, got "
                f"{self.pose.gap.shape}"
            )
        object.__setattr__(self, "thickness", thickness)

    @classmethod
    def from_load(cls, part: BodyPart, thickness, load: Load, **meta) -> "Scene":
        return cls(part, thickness, load.force, load, dict(meta))

    @classmethod
    def posed(cls, part: BodyPart, thickness, pose: Pose, **meta) -> "Scene":
        """A scene given by where objects are (see :mod:`stmpl.pose`)."""
        return cls(part, thickness, None, None, dict(meta), pose)

    @property
    def given(self) -> str:
        """``"force"`` or ``"pose"``: what the scene gives (the other is what is asked)."""
        return "force" if self.pose is None else "pose"

    def _force(self) -> np.ndarray:
        if self.force is None:
            raise ValueError(
                "this scene gives an object's pose, not a force: the force is in its answer "
                "(Deformation.force, Deformation.reaction)"
            )
        return self.force

    @property
    def total_force(self) -> float:
        """Sum of the per-vertex forces, N."""
        return float(self._force().sum())

    @property
    def force_vectors(self) -> np.ndarray:
        """``(N, 3)`` force vectors, N (along the inward normal)."""
        return -self._force()[:, None] * self.part.normals

    def header(self) -> dict:
        return {
            "format": FORMAT,
            "part": self.part.name,
            "source": self.part.source,
            "load": self.load.to_dict() if self.load else None,
            "meta": self.meta,
            "pose": None if self.pose is None else {"objects": self.pose.names()},
        }

    def arrays(self) -> dict:
        """The scene's arrays for a file: the part's, the thickness, the force or the pose."""
        arrays = {f"part/{k}": v for k, v in self.part.arrays().items()}
        arrays["thickness"] = self.thickness
        if self.pose is None:
            arrays["force"] = self.force
        else:
            arrays.update({f"pose/{k}": v for k, v in self.pose.arrays().items()})
        return arrays

    def save(self, path) -> pathlib.Path:
        """Write the scene to ``path`` (``.npz``); :meth:`read` reads it back."""
        return _save(path, self.arrays(), self.header())

    @classmethod
    def read(cls, path) -> "Scene":
        """Read a scene written by :meth:`save` (``.npz``; its load's summary is not kept)."""
        arrays, header = _read_file(path, FORMAT)
        try:
            part = BodyPart.from_arrays(
                header["part"],
                {k[5:]: v for k, v in arrays.items() if k.startswith("part/")},
                header.get("source"),
            )
            meta = header.get("meta", {})
            if header.get("pose"):
                got = {k[5:]: v for k, v in arrays.items() if k.startswith("pose/")}
                pose = Pose.from_arrays(got, header["pose"]["objects"])
                return cls.posed(part, arrays["thickness"], pose, **meta)
            return cls(part, arrays["thickness"], arrays["force"], None, meta)
        except KeyError as exc:
            raise ValueError(f"scene file {path} lacks {exc}") from exc


@dataclass(frozen=True, eq=False)
class Deformation:
    """The response of a scene: ``displacement`` ``(N, 3)`` m per vertex of ``scene.part``.

    For a scene given by a pose, also ``force`` ``(N,)``: the contact force the objects put on
    each vertex, N (the contact pressure times the vertex's area, along the inward normal), and
    ``reaction``: the force the objects must be pushed with along the pose's direction, N. For
    a scene given by its force both are ``None`` (the force is the scene's).

    ``info`` carries diagnostics (predictor name, timings, solver residuals).
    """

    scene: Scene
    displacement: np.ndarray
    info: dict = field(default_factory=dict)
    force: np.ndarray | None = None
    reaction: float | None = None

    def __post_init__(self) -> None:
        u = np.asarray(self.displacement, dtype=float)
        n = self.scene.part.n_vertices
        if u.shape != (n, 3):
            raise ValueError(f"Deformation.displacement must have shape ({n}, 3), got {u.shape}")
        if not np.isfinite(u).all():
            raise ValueError("Deformation.displacement contains non-finite values")
        u = u.copy()
        u.setflags(write=False)
        object.__setattr__(self, "displacement", u)
        if self.scene.pose is None:
            if self.force is not None or self.reaction is not None:
                raise ValueError(
                    "a scene given by its force has no answered force or reaction (they are "
                    "the scene's own)"
                )
            return
        if self.force is None or self.reaction is None:
            raise ValueError("the answer to a posed scene needs its force and its reaction")
        f = np.asarray(self.force, dtype=float)
        if f.shape != (n,) or not np.isfinite(f).all() or (f < 0).any():
            raise ValueError(
                f"Deformation.force must be ({n},) finite forces >= 0 N, got shape {f.shape}"
            )
        r = float(self.reaction)
        if not np.isfinite(r):
            raise ValueError(f"Deformation.reaction must be finite, got {self.reaction!r}")
        f = f.copy()
        f.setflags(write=False)
        object.__setattr__(self, "force", f)
        object.__setattr__(self, "reaction", r)

    @property
    def applied(self) -> np.ndarray:
        """``(N,)`` the force on each vertex, N: the scene's, or the answer's for a posed scene."""
        return self.scene.force if self.force is None else self.force

    @property
    def pressure(self) -> np.ndarray:
        """``(N,)`` contact pressure on each vertex, Pa (a posed scene's answer only)."""
        if self.force is None:
            raise ValueError("only the answer to a posed scene has a contact pressure")
        return self.force / self.scene.part.vertex_areas

    @property
    def vertices(self) -> np.ndarray:
        """``(N, 3)`` deformed positions, m."""
        return self.scene.part.vertices + self.displacement

    @property
    def magnitude(self) -> np.ndarray:
        """``(N,)`` displacement length, m."""
        return np.linalg.norm(self.displacement, axis=1)

    def mesh(self):
        """The deformed part as a ``trimesh.Trimesh``."""
        return self.scene.part.mesh(self.vertices)

    def save(self, path) -> pathlib.Path:
        arrays = {**self.scene.arrays(), "displacement": self.displacement}
        header = {**self.scene.header(), "info": self.info}
        if self.force is not None:
            arrays["answer/force"] = self.force
            header["reaction"] = self.reaction
        return _save(path, arrays, header)

    @classmethod
    def read(cls, path) -> "Deformation":
        """Read a deformation written by :meth:`save` (``.npz``)."""
        arrays, header = _read_file(path, FORMAT)
        if "displacement" not in arrays:
            raise ValueError(f"{path} holds a scene, not a deformation (no displacement)")
        scene = Scene.read(path)
        force = arrays.get("answer/force")
        return cls(
            scene, arrays["displacement"], header.get("info", {}), force, header.get("reaction")
        )


def _save(path, arrays: dict, header: dict) -> pathlib.Path:
    arrays = dict(arrays, header=np.frombuffer(json.dumps(header).encode(), dtype=np.uint8))
    return atomic_savez(path, arrays, compressed=True)


def _read_file(path, fmt: str) -> tuple[dict, dict]:
    path = pathlib.Path(path)
    if not path.exists():
        raise FileNotFoundError(f"scene file not found: {path}")
    try:
        with np.load(path, allow_pickle=False) as z:
            arrays = {k: z[k] for k in z.files}
        header = json.loads(bytes(arrays.pop("header")).decode())
    except Exception as exc:
        raise ValueError(f"{path} is not a readable stmpl scene file: {exc}") from exc
    if header.get("format") != fmt:
        raise ValueError(f"{path}: format {header.get('format')!r}, expected {fmt!r}")
    return arrays, header
