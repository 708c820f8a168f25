"""What the command line's options build: the body, a part's tissue, a load, a scene (the
options themselves are declared in :mod:`stmpl.cli.arguments`).
"""

from __future__ import annotations

from stmpl import loads, tissue
from stmpl.body.phenotype import PHENOTYPES
from stmpl.body.spec import body_from_spec
from stmpl.cli.arguments import MM
from stmpl.scene import Scene


def phenotype_of(args) -> dict[str, float]:
    """The anny phenotype the options name (the ones given)."""
    return {k: getattr(args, k) for k in PHENOTYPES if getattr(args, k, None) is not None}


def body_spec_of(args) -> dict:
    """The body spec (:mod:`stmpl.body.spec`) the options describe."""
    if getattr(args, "smpl", None):
        betas = [0.0, args.beta2] if args.beta2 is not None else None
        return {"model": "smpl", "path": args.smpl, "uv_path": args.smpl_uv, "betas": betas}
    return {"model": "anny", "phenotype": phenotype_of(args)}


def body_of(args):
    """The body model the options describe."""
    return body_from_spec(body_spec_of(args))


def thickness_of(args, part):
    """``(N,)`` m: the tissue the options give ``part``."""
    if args.thickness is not None:
        return tissue.constant(part, args.thickness * MM)
    if getattr(args, "smpl", None):
        return tissue.from_beta2(part, args.beta2 or 0.0)
    return tissue.from_weight(part, args.weight)


def load_of(args, part):
    """The primitive :class:`~stmpl.loads.Load` the options describe on ``part``."""
    total, uv = args.force, tuple(args.at)
    if args.load == "disk":
        return loads.disk(part, radius=args.radius * MM, total=total, uv=uv)
    if args.load == "ellipse":
        axes = (args.radius * MM, args.radius * MM / 2)
        return loads.ellipse(part, semi_axes=axes, angle=args.angle, total=total, uv=uv)
    if args.load == "seam_disk":
        return loads.seam_disk(part, args.along, args.radius * MM, total)
    if args.load == "spots":
        return loads.spots(
            part,
            count=args.count,
            radius=args.radius * MM,
            spread=args.spread * MM,
            total=total,
            uv=uv,
        )
    if args.load == "band":
        return loads.band(part, args.along, args.width * MM, total)
    return loads.letter(
        part, args.char, uv, args.char_height * MM, args.width * MM, args.angle, total
    )


def scene_of(args, subdivisions: int = 0) -> Scene:
    """The primitive scene the options describe, on the part subdivided ``subdivisions`` times
    (its load's summary printed).
    """
    body = body_of(args)
    part = body.part(args.part).subdivided(subdivisions)
    load = load_of(args, part)
    print(load.summary())
    return Scene.from_load(part, thickness_of(args, part), load, body=body.name)
