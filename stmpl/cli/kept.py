"""The FEM's answers ``--compare`` keeps on disk, so that the same check run again answers in
seconds: a grip on the layered forearm takes the FEM an hour or more, and a user who runs the
main job again with another model, or redraws its picture, asks it the same question.

An answer is kept under a key of everything that decides it: the scene's arrays (the part, the
thickness, the force or the pose), the FEM's set-up as the command gives it (resolution,
levels, fidelity, tissue, phenotype, friction, a target force), the stmpl version and the
source code of stmpl and of the package the FEM predictor comes from. Any change to either
code base, or to the scene, is another key: a kept answer is only ever one the same code gave
to the same question. Failed solves are not kept (they are solved again). Files live in
stmpl's cache directory (``answers/``); a file that cannot be read is solved again.
"""

from __future__ import annotations

import functools
import hashlib
import json
import pathlib
import sys
from importlib import metadata

import numpy as np

from stmpl.body.model import default_cache_dir
from stmpl.scene import Deformation, Scene

KEPT_VERSION = 1
"""Bumped when what a kept answer's file holds changes meaning."""


@functools.lru_cache(maxsize=8)
def sources(package: str) -> str:
    """The SHA-256 of the ``.py`` files of an imported ``package`` (its directory, sorted by
    path, each path beside its bytes), hex.
    """
    mod = sys.modules.get(package)
    if mod is None or getattr(mod, "__file__", None) is None:
        raise ValueError(f"package {package!r} is not imported: its sources cannot be read")
    root = pathlib.Path(mod.__file__).parent
    h = hashlib.sha256()
    for p in sorted(root.rglob("*.py")):
        h.update(str(p.relative_to(root)).encode())
        h.update(p.read_bytes())
    return h.hexdigest()


def code_of(fem) -> dict:
    """What code decides the answers of the predictor ``fem``: stmpl's version and the digests
    of stmpl's sources and of the package ``fem``'s class comes from.
    """
    package = type(fem).__module__.split(".")[0]
    try:
        version = metadata.version("stmpl")
    except metadata.PackageNotFoundError:
        version = "unknown"
    return {"stmpl": version, "sources": {p: sources(p) for p in sorted({"stmpl", package})}}


def key(scene: Scene, setup: dict, code: dict) -> str:
    """The key of ``scene``'s answer by a FEM set up as ``setup`` (JSON values) running
    ``code`` (:func:`code_of`): 24 hex digits of a SHA-256.
    """
    h = hashlib.sha256(
        json.dumps([KEPT_VERSION, setup, code], sort_keys=True, default=str).encode()
    )
    for name, a in sorted(scene.arrays().items()):
        a = np.ascontiguousarray(a)
        h.update(f"{name}:{a.dtype.str}:{a.shape}".encode())
        h.update(a.tobytes())
    return h.hexdigest()[:24]


def path(k: str) -> pathlib.Path:
    """The file of the answer kept under key ``k``."""
    return default_cache_dir() / "answers" / f"{k}.npz"


def read(k: str) -> Deformation | None:
    """The answer kept under key ``k``, its ``info["kept"]`` saying from which file; ``None``
    when none is kept or its file cannot be read (it is then removed, to be solved again).
    """
    p = path(k)
    if not p.is_file():
        return None
    try:
        d = Deformation.read(p)
    except (OSError, ValueError, KeyError):
        p.unlink(missing_ok=True)
        return None
    d.info["kept"] = str(p)
    return d


def write(k: str, d: Deformation) -> pathlib.Path | None:
    """Keep the answer ``d`` under key ``k``; ``None`` (nothing kept) where its diagnostics are
    not JSON or the cache directory cannot be written: the answer stands either way.
    """
    try:
        info = json.loads(json.dumps(d.info, default=_plain))
        return Deformation(d.scene, d.displacement, info, d.force, d.reaction).save(path(k))
    except (OSError, TypeError, ValueError):
        return None


def _plain(x):
    """A NumPy value in an answer's diagnostics as JSON takes it."""
    if isinstance(x, np.generic | np.ndarray):
        return x.tolist()
    raise TypeError(f"{type(x).__name__} is not JSON")
