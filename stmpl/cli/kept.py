"""The FEM's answers ``--compare`` keeps on disk, so that the same check run again answers in
seconds: a grip on the layered forearm takes the FEM an hour or more, and a user who runs the
main job again with another model, or redraws its picture, asks it the same question.

An answer is kept under a key of everything that decides it: the scene's arrays (the part, the
thickness, the force or the pose), the FEM's set-up as the command gives it (resolution,
levels, fidelity, tissue, and a tissue file's own bytes, phenotype, friction, a target force),
the stmpl version and the source code the FEM predictor runs: its module and every module it
imports, followed through stmpl and the FEM's package (an import anywhere in a file counts, and
so does a module named in a string, as lazy exports name them). A change to any of those files,
or to the scene, is another key: a kept answer is only ever one the same code gave to the same
question, while a change elsewhere (the command line, a learned model) keeps it. Failed solves
are not kept (they are solved again). Files live in stmpl's cache directory (``answers/``); a
file that cannot be read is solved again.
"""

from __future__ import annotations

import ast
import functools
import hashlib
import importlib.util
import json
import pathlib
import re
from importlib import metadata

import numpy as np

from stmpl.body.model import default_cache_dir
from stmpl.scene import Deformation, Scene

KEPT_VERSION = 1
"""Bumped when what a kept answer's file holds changes meaning."""


def module_file(name: str) -> pathlib.Path | None:
    """The source file of module ``name`` (a package's ``__init__.py``) if it can be found
    without importing it, else ``None``.
    """
    try:
        spec = importlib.util.find_spec(name)
    except (ImportError, ValueError):
        return None
    if spec is None or not spec.origin or not spec.origin.endswith(".py"):
        return None
    return pathlib.Path(spec.origin)


def named_modules(path: pathlib.Path, name: str) -> set[str]:
    """The modules the file ``path`` of module ``name`` may import: its import statements
    (anywhere in the file, relative ones resolved), each ``from m import x`` also as ``m.x``
    (``x`` may be a module), and every string that reads as a dotted name.
    """
    tree = ast.parse(path.read_bytes(), filename=str(path))
    package = name if path.name == "__init__.py" else name.rpartition(".")[0]
    out = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            out.update(a.name for a in node.names)
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                parts = package.split(".")[: len(package.split(".")) - node.level + 1]
                base = ".".join(parts + ([base] if base else []))
            out.add(base)
            out.update(f"{base}.{a.name}" for a in node.names)
        elif isinstance(node, ast.Constant) and isinstance(node.value, str):
            if re.fullmatch(r"[A-Za-z_]\w*(\.[A-Za-z_]\w*)+", node.value):
                out.add(node.value)
    return out


@functools.lru_cache(maxsize=8)
def sources(module: str, packages: tuple[str, ...]) -> dict[str, str]:
    """``{file: SHA-256}`` of ``module``'s source and of every module it imports, followed
    (:func:`named_modules`) within the top-level ``packages``; files by their path relative to
    their package's parent, sorted.
    """
    if module_file(module) is None:
        raise ValueError(f"module {module!r} has no source file: its code cannot be read")
    seen: dict[str, pathlib.Path] = {}
    todo = [module]
    while todo:
        name = todo.pop()
        if name in seen or name.split(".")[0] not in packages:
            continue
        path = module_file(name)
        if path is None:
            continue
        seen[name] = path
        parts = name.split(".")
        todo += [".".join(parts[:i]) for i in range(1, len(parts))]  # the packages above it
        todo += sorted(named_modules(path, name))
    out = {}
    for name, path in seen.items():
        depth = name.count(".") + (path.name == "__init__.py")
        out[str(path.relative_to(path.parents[depth]))] = hashlib.sha256(
            path.read_bytes()
        ).hexdigest()
    return dict(sorted(out.items()))


def code_of(fem) -> dict:
    """What code decides the answers of the predictor ``fem``: stmpl's version and the digest
    of the sources its class's module runs (:func:`sources`, within stmpl and its package).
    """
    module = type(fem).__module__
    try:
        version = metadata.version("stmpl")
    except metadata.PackageNotFoundError:
        version = "unknown"
    files = sources(module, tuple(sorted({"stmpl", module.split(".")[0]})))
    digest = hashlib.sha256(json.dumps(files, sort_keys=True).encode()).hexdigest()
    return {"stmpl": version, "module": module, "sources": digest}


def setup_of(options: dict) -> dict:
    """The FEM's set-up ``options`` as a key holds it: a tissue given as a YAML file also by
    the SHA-256 of its bytes (the file read again when it changes).
    """
    out = dict(options)
    t = out.get("tissue")
    if isinstance(t, str) and t.endswith((".yaml", ".yml")) and pathlib.Path(t).is_file():
        out["tissue_sha256"] = hashlib.sha256(pathlib.Path(t).read_bytes()).hexdigest()
    return out


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
