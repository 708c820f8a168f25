"""The body-model protocol, part specifications and the on-disk part cache.

A body model gives a whole-body rest mesh (:class:`BodyMesh`) and cuts named parts from it
(:class:`PartSpec`: skinning bones plus an optional side). Parts are cached as ``.npz`` files keyed
by the model's options, the part name and :data:`CACHE_VERSION`.
"""

from __future__ import annotations

import hashlib
import json
import logging
import os
import pathlib
from dataclasses import dataclass
from typing import Protocol, runtime_checkable

import numpy as np

from stmpl.body.extract import extract_part
from stmpl.files import atomic_savez
from stmpl.part import BodyPart

log = logging.getLogger(__name__)

CACHE_VERSION = 3
"""Bump when part extraction changes: every cached part is rebuilt (3: front-only parts cut on
the template shape)."""


def default_cache_dir() -> pathlib.Path:
    """``$STMPL_CACHE_DIR`` or ``~/.cache/stmpl``."""
    return pathlib.Path(os.environ.get("STMPL_CACHE_DIR", pathlib.Path.home() / ".cache" / "stmpl"))


@dataclass(frozen=True)
class BodyMesh:
    """A whole-body rest mesh with skinning and UVs.

    vertices ``(V, 3)`` m; faces ``(F, 3)``; uv ``(T, 2)`` atlas; face_uv ``(F, 3)``;
    dominant_bone ``(V,)`` index into ``bone_labels``; bone_heads ``(J, 3)`` m;
    forward ``(3,)`` unit vector pointing out of the body's front.
    """

    vertices: np.ndarray
    faces: np.ndarray
    uv: np.ndarray
    face_uv: np.ndarray
    dominant_bone: np.ndarray
    bone_labels: tuple[str, ...]
    bone_heads: np.ndarray
    forward: np.ndarray


@dataclass(frozen=True)
class PartSpec:
    """Which vertices form a part: those whose dominant skinning bone is in ``bones``; with
    ``front_only``, only those in front of the bones' mean head (along the body's forward axis),
    judged on the model's template shape (:meth:`CachedBodyModel.template_mesh`) so that every
    shape of the body cuts the same vertices: one mesh, whatever the phenotype or betas.
    ``axis_bones`` list the bone heads of the limb centre line, proximal to distal.
    """

    bones: tuple[str, ...]
    axis_bones: tuple[str, ...] = ()
    front_only: bool = False


@runtime_checkable
class BodyModel(Protocol):
    """What every body model offers."""

    name: str

    def part_names(self) -> list[str]: ...

    def part(self, name: str = "left_arm") -> BodyPart: ...

    def rest_mesh(self) -> BodyMesh: ...


class CachedBodyModel:
    """Shared machinery: part lookup, validation, the on-disk cache. Subclasses define
    ``name``, ``PARTS`` (name -> PartSpec), :meth:`rest_mesh` and :meth:`options`.
    """

    name = "body"
    PARTS: dict[str, PartSpec] = {}

    def __init__(self, cache_dir: str | os.PathLike | None = None) -> None:
        self.cache_dir = pathlib.Path(cache_dir) if cache_dir else default_cache_dir()

    def options(self) -> dict:
        """JSON-serialisable options that determine the mesh (part of the cache key)."""
        raise NotImplementedError

    def rest_mesh(self) -> BodyMesh:
        raise NotImplementedError

    def template_mesh(self) -> BodyMesh:
        """The rest mesh of the model's template shape (anny's phenotype 0.5 everywhere, SMPL's
        zero betas): where shape-dependent part boundaries are drawn. Default: the rest mesh.
        """
        return self.rest_mesh()

    def part_names(self) -> list[str]:
        return list(self.PARTS)

    def part(self, name: str = "left_arm") -> BodyPart:
        """The named part in the rest pose, from the cache when it is there."""
        if name not in self.PARTS:
            raise ValueError(
                f"unknown part {name!r} for body model {self.name!r}; "
                f"known parts: {', '.join(self.PARTS)}"
            )
        source = {
            "body": self.name,
            "options": self.options(),
            "part": name,
            "cache_version": CACHE_VERSION,
        }
        key = hashlib.sha256(json.dumps(source, sort_keys=True).encode()).hexdigest()[:20]
        path = self.cache_dir / "parts" / f"{self.name}-{name}-{key}.npz"
        if path.exists():
            try:
                with np.load(path) as z:
                    return BodyPart.from_arrays(name, dict(z), source)
            except Exception as exc:  # a corrupt cache entry is rebuilt, never trusted
                log.warning("rebuilding corrupt part cache %s (%s)", path, exc)
        part = self._build_part(name, source)
        atomic_savez(path, part.arrays())
        return part

    def _build_part(self, name: str, source: dict) -> BodyPart:
        spec, mesh = self.PARTS[name], self.rest_mesh()
        labels = list(mesh.bone_labels)
        missing = [b for b in spec.bones + spec.axis_bones if b not in labels]
        if missing:
            raise ValueError(f"part {name!r}: bones {missing} not in body model {self.name!r}")
        ids = [labels.index(b) for b in spec.bones]
        mask = np.isin(mesh.dominant_bone, ids)
        if spec.front_only:  # on the template: the same cut for every shape
            t = self.template_mesh()
            centre = t.bone_heads[ids].mean(axis=0)
            mask &= (t.vertices - centre) @ t.forward > 0
        axis = (
            mesh.bone_heads[[labels.index(b) for b in spec.axis_bones]] if spec.axis_bones else None
        )
        log.info("building part %s of %s", name, self.name)
        return extract_part(
            name, mesh.vertices, mesh.faces, mesh.uv, mesh.face_uv, mask, axis=axis, source=source
        )
