"""Bodies and parts from a spec: the mapping a dataset config's ``body`` entry holds and the
command line builds, ``{"model": "anny" | "smpl" | "tube" | "sheet", ...}``. The one place a
body is built from a description.

>>> part_from_spec({"model": "anny", "phenotype": {"weight": 0.25}}, "left_arm")
>>> part_from_spec({"model": "tube", "radius": 0.04, "length": 0.2}, "tube")
"""

from __future__ import annotations

from stmpl.body import primitives
from stmpl.body.anny_body import AnnyBody
from stmpl.body.smpl_body import SMPLBody
from stmpl.part import BodyPart

KEYS = {
    "anny": {"model", "phenotype", "subdivisions"},
    "smpl": {"model", "path", "uv_path", "betas", "subdivisions"},
    "tube": {"model", "radius", "length", "n_around", "n_along", "taper", "subdivisions"},
    "sheet": {"model", "width", "height", "nx", "ny", "subdivisions"},
}
"""The keys each body model takes; ``subdivisions`` (any model) splits every triangle of the
part into four that many times (:func:`stmpl.part.subdivide`), for a finer skin."""
PRIMITIVES = ("tube", "sheet")
SHAPE_KEYS = {
    "anny": {"phenotype"},
    "smpl": {"betas"},
    "tube": {"radius", "length", "taper"},
    "sheet": {"width", "height"},
}
"""The keys that change a body's shape but not its mesh (the same vertices, faces and chart in
another place): datasets differing only in them are one mesh on several bodies."""


def check_spec(spec) -> dict:
    """``spec`` if it names a known model with only that model's keys; else ``ValueError``."""
    if not isinstance(spec, dict) or spec.get("model") not in KEYS:
        raise ValueError(f"body.model must be one of {sorted(KEYS)}, got {spec!r}")
    bad = set(spec) - KEYS[spec["model"]]
    if bad:
        raise ValueError(
            f"unknown body keys {sorted(bad)} for model {spec['model']!r}; it "
            f"takes {sorted(KEYS[spec['model']] - {'model'})}"
        )
    k = spec.get("subdivisions", 0)
    if isinstance(k, bool) or not isinstance(k, int) or not 0 <= k <= 3:
        raise ValueError(f"body.subdivisions must be an integer 0..3, got {k!r}")
    if spec["model"] == "smpl" and not spec.get("path"):
        raise ValueError("body.path: an SMPL-format body needs the model file's path")
    return spec


def body_from_spec(spec: dict):
    """The body model of an ``anny`` or ``smpl`` spec (an analytic tube or sheet is a part, not
    a body: use :func:`part_from_spec`).
    """
    spec = dict(check_spec(spec))
    model = spec.pop("model")
    spec.pop("subdivisions", None)
    if model in PRIMITIVES:
        raise ValueError(f"a {model} is a single part, not a body with parts")
    if model == "smpl":
        return SMPLBody(spec["path"], uv_path=spec.get("uv_path"), betas=spec.get("betas"))

    return AnnyBody(phenotype=spec.get("phenotype") or {})


def part_from_spec(spec: dict, part: str) -> BodyPart:
    """The part called ``part`` of the body ``spec`` describes (for a tube or sheet, the
    primitive itself).
    """
    check_spec(spec)
    if spec["model"] in PRIMITIVES:
        kwargs = {k: v for k, v in spec.items() if k not in ("model", "subdivisions")}
        out = getattr(primitives, spec["model"])(**kwargs)
    else:
        out = body_from_spec(spec).part(part)
    return out.subdivided(spec.get("subdivisions", 0))
