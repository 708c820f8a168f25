"""The default body model: Anny (Apache-2.0 code, CC0 MakeHuman assets, shipped with the package).

Anny builds its assets once (about a minute) into ``$ANNY_CACHE_DIR`` (default ``~/.cache/anny``);
stmpl caches the parts it cuts from it, so later runs never touch Anny at all.
"""

from __future__ import annotations

import contextlib
import logging
import math
import os
import sys
import tempfile
from importlib.metadata import version

import numpy as np

from stmpl.body.model import BodyMesh, CachedBodyModel, PartSpec
from stmpl.body.phenotype import PHENOTYPES
from stmpl.part import BodyPart

log = logging.getLogger(__name__)


_ARM = ("upperarm01", "upperarm02", "lowerarm01", "lowerarm02")


def _arm(side: str) -> PartSpec:
    return PartSpec(
        bones=tuple(f"{b}.{side}" for b in _ARM),
        axis_bones=(f"upperarm01.{side}", f"lowerarm01.{side}", f"wrist.{side}"),
    )


WARP_NOISE = ("Warp CUDA warning", "Warp CUDA error: Failed to get driver entry point")
"""Lines NVIDIA Warp's native library writes to stderr when it initialises on a machine without
a CUDA driver: noise on a CPU machine, dropped (anything else it writes is kept)."""


@contextlib.contextmanager
def _without_native_lines(prefixes: tuple):
    """Run the block with file descriptor 2 (native code's stderr) captured, then write back
    every captured line that does not start with one of ``prefixes``.
    """
    sys.stderr.flush()
    try:
        saved = os.dup(2)
    except OSError:  # pragma: no cover - no stderr to capture
        yield
        return
    with tempfile.TemporaryFile() as tmp:
        os.dup2(tmp.fileno(), 2)
        try:
            yield
        finally:
            sys.stderr.flush()
            os.dup2(saved, 2)
            os.close(saved)
            tmp.seek(0)
            kept = [
                ln
                for ln in tmp.read().decode(errors="replace").splitlines(keepends=True)
                if not ln.startswith(prefixes)
            ]
            if kept:
                sys.stderr.write("".join(kept))
                sys.stderr.flush()


class AnnyBody(CachedBodyModel):
    """Anny in its rest pose with the given phenotype.

    Args:
        phenotype: values in [0, 1] for any of :data:`PHENOTYPES` (others stay 0.5).
        cache_dir: where parts are cached (default ``$STMPL_CACHE_DIR`` or ``~/.cache/stmpl``).
    """

    name = "anny"
    PARTS = {
        "left_arm": _arm("L"),
        "right_arm": _arm("R"),
        "belly": PartSpec(bones=("spine03", "spine04"), front_only=True),
    }

    def __init__(self, phenotype: dict[str, float] | None = None, cache_dir=None) -> None:
        super().__init__(cache_dir)
        self.phenotype = check_phenotype(phenotype or {})
        self._anny = None
        self._mesh: BodyMesh | None = None

    @property
    def weight(self) -> float:
        """The ``weight`` phenotype (0 thin .. 1 heavy)."""
        return self.phenotype.get("weight", 0.5)

    def options(self) -> dict:

        return {
            "phenotype": {k: self.phenotype.get(k, 0.5) for k in PHENOTYPES},
            "anny_version": version("anny"),
        }

    @property
    def anny(self):
        """The underlying ``anny.Anny`` module (built on first use)."""
        if self._anny is None:
            try:  # anny's skinning initialises NVIDIA Warp, which prints a banner otherwise
                import warp  # deferred: anny's kernels

                warp.config.log_level = warp.LOG_ERROR
            except ImportError:  # pragma: no cover
                pass
            cache = os.path.expanduser(os.environ.get("ANNY_CACHE_DIR", "~/.cache/anny"))
            if not os.path.isdir(cache) or not os.listdir(cache):
                log.warning("building anny's assets once into %s (about a minute)", cache)
            with _without_native_lines(WARP_NOISE):
                import anny  # deferred: the body model's assets (torch, warp)

                self._anny = anny.Anny()
        return self._anny

    def rest_mesh(self) -> BodyMesh:
        if self._mesh is None:
            self._mesh = self._rest_mesh(self.phenotype)
        return self._mesh

    def template_mesh(self) -> BodyMesh:
        """The rest mesh at phenotype 0.5 everywhere (anny's template shape)."""
        if all(abs(v - 0.5) < 1e-12 for v in self.phenotype.values()):
            return self.rest_mesh()
        return self._rest_mesh({})

    def _rest_mesh(self, phenotype: dict[str, float]) -> BodyMesh:
        """The whole-body rest mesh of ``phenotype`` (unset values 0.5)."""
        import torch  # deferred: anny's forward pass (about a second to import)

        m = self.anny
        with torch.no_grad():
            out = m(phenotype_kwargs={k: float(v) for k, v in phenotype.items()})
        w, bi = m.vertex_bone_weights.numpy(), m.vertex_bone_indices.numpy()
        return BodyMesh(
            vertices=out["rest_vertices"][0].double().numpy(),
            faces=m.faces.numpy().astype(np.int64),
            uv=m.texture_coordinates.double().numpy(),
            face_uv=m.face_texture_coordinate_indices.numpy().astype(np.int64),
            dominant_bone=bi[np.arange(len(bi)), w.argmax(axis=1)],
            bone_labels=tuple(m.bone_labels),
            bone_heads=out["rest_bone_heads"][0].double().numpy(),
            forward=np.array([0.0, -1.0, 0.0]),  # anny: z up, the face looks along -y
        )


def check_phenotype(phenotype: dict[str, float]) -> dict[str, float]:
    """Validate phenotype values: known names, finite, in [0, 1]."""
    out = {}
    for k, v in phenotype.items():
        if k not in PHENOTYPES:
            raise ValueError(f"unknown anny phenotype {k!r}; known: {', '.join(PHENOTYPES)}")
        v = float(v)
        if not math.isfinite(v) or not 0.0 <= v <= 1.0:
            raise ValueError(f"anny phenotype {k} must be in [0, 1], got {v}")
        out[k] = v
    return out


def default_part(name: str = "left_arm", weight: float = 0.5) -> BodyPart:
    """The named part of the default body (Anny) with the given ``weight`` phenotype."""
    return AnnyBody(phenotype={"weight": weight}).part(name)
