"""What a predictor takes and gives: a :class:`Scene` (a part, its tissue thickness and the
external normal force) and a :class:`Deformation` (a displacement per vertex).

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

FORMAT = "stmpl-scene/1"


@dataclass(frozen=True, eq=False)
class Scene:
    """A body part under load.

    Attributes:
        part: the body part (rest pose).
        thickness: ``(N,)`` soft-tissue thickness per vertex, m, in ``tissue.THICKNESS_RANGE``.
        force: ``(N,)`` normal force per vertex, N, >= 0, pushing along ``-part.normals``.
        load: the load that made ``force`` (optional, for reports).
        meta: free JSON-serialisable notes (e.g. phenotype, placement id).
    """

    part: BodyPart
    thickness: np.ndarray
    force: np.ndarray
    load: Load | None = None
    meta: dict = field(default_factory=dict)

    def __post_init__(self) -> None:
        t = tissue.check(self.part, self.thickness)
        f = np.asarray(self.force, dtype=float)
        n = self.part.n_vertices
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

    @classmethod
    def from_load(cls, part: BodyPart, thickness, load: Load, **meta) -> "Scene":
        return cls(part, thickness, load.force, load, dict(meta))

    @property
    def total_force(self) -> float:
        """Sum of the per-vertex forces, N."""
        return float(self.force.sum())

    @property
    def force_vectors(self) -> np.ndarray:
        """``(N, 3)`` force vectors, N (along the inward normal)."""
        return -self.force[:, None] * self.part.normals

    def header(self) -> dict:
        return {
            "format": FORMAT,
            "part": self.part.name,
            "source": self.part.source,
            "load": self.load.to_dict() if self.load else None,
            "meta": self.meta,
        }

    def save(self, path) -> pathlib.Path:
        """Write the scene to ``path`` (``.npz``); :meth:`read` reads it back."""
        arrays = {f"part/{k}": v for k, v in self.part.arrays().items()}
        arrays.update(thickness=self.thickness, force=self.force)
        return _save(path, arrays, self.header())

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
            return cls(part, arrays["thickness"], arrays["force"], None, header.get("meta", {}))
        except KeyError as exc:
            raise ValueError(f"scene file {path} lacks {exc}") from exc


@dataclass(frozen=True, eq=False)
class Deformation:
    """The response of a scene: ``displacement`` ``(N, 3)`` m per vertex of ``scene.part``.

    ``info`` carries diagnostics (predictor name, timings, solver residuals).
    """

    scene: Scene
    displacement: np.ndarray
    info: dict = field(default_factory=dict)

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
        arrays = {f"part/{k}": v for k, v in self.scene.part.arrays().items()}
        arrays.update(
            thickness=self.scene.thickness, force=self.scene.force, displacement=self.displacement
        )
        return _save(path, arrays, {**self.scene.header(), "info": self.info})

    @classmethod
    def read(cls, path) -> "Deformation":
        """Read a deformation written by :meth:`save` (``.npz``)."""
        arrays, header = _read_file(path, FORMAT)
        if "displacement" not in arrays:
            raise ValueError(f"{path} holds a scene, not a deformation (no displacement)")
        scene = Scene.read(path)
        return cls(scene, arrays["displacement"], header.get("info", {}))


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
