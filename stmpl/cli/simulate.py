"""The main job, ``stmpl simulate``: an object pressed on a body part (by default anny's right
hand closing on the layered tissue of her left forearm until it squeezes 5 N), predicted by a
shipped model (and any other), with ``--compare`` the FEM beside it; it writes the deformed body
(GLB with the object in place, and PLY) and a picture, and prints each method's time, reaction
and contact pressure.

>>> stmpl simulate                                     # the default grasp of real tissue
>>> stmpl simulate --force 2 --grip tripod --compare   # a tripod, checked by the FEM
>>> stmpl simulate --tissue paper                      # the paper's gel, its 0.4 N grasp
>>> stmpl simulate --tissue paper --grip pinch --along 0.5 --compare
>>> stmpl simulate --letters ECCV --force 0.3 --model zoo:uv_unet_arm_bodies
>>> stmpl simulate --weight 0.9 --muscle 0.2 --part right_arm  # another body, its right arm
>>> stmpl simulate --object tool.stl --at 0.45 0.5 --depth 3
>>> stmpl simulate --sphere 8 --depth 3 --given pose --model fem --tissue forearm --res medium
>>> stmpl simulate --grip pinch --depth 2 --given pose --model fem --tissue forearm --res medium
>>> stmpl simulate --sphere 8 --depth 1 --given pose --force 5 --model fem --tissue forearm
"""

from __future__ import annotations

import json
import pathlib
import time

import numpy as np

import stmpl.contact.pressing as contact
from stmpl.body.spec import part_from_spec
from stmpl.cli import answers
from stmpl.cli.arguments import (
    GRASP_FORCE_N,
    GRASP_MODEL,
    GRASP_RESOLUTION,
    GRASP_TISSUE,
    default_model,
)
from stmpl.cli.options import phenotype_of, thickness_of
from stmpl.contact import objects
from stmpl.contact.grips import GRIPS
from stmpl.contact.hand import Hand, cached_grasp, palm_press
from stmpl.contact.posing import gripped, posed
from stmpl.files import atomic_write_text
from stmpl.mesh import Mesh
from stmpl.scene import Scene
from stmpl.viz.figures import export_mesh, glb_extras, vertex_colors
from stmpl.viz.meshfile import glb_bytes
from stmpl.viz.render import contact_figure
from stmpl.viz.verdict import facts


def pressings(args, part) -> list:
    """The :class:`~stmpl.contact.pressing.Pressing` objects the options describe."""
    mm = 1e-3
    chosen = [k for k in ("object", "sphere", "letters") if getattr(args, k) is not None] + (
        ["strap"] if args.strap else []
    )
    if args.object is not None and not args.object.strip():
        raise ValueError("--object needs a mesh file's path, got an empty one")
    if args.sphere is not None and not (np.isfinite(args.sphere) and args.sphere > 0):
        raise ValueError(f"--sphere needs a radius above 0 mm, got {args.sphere:g}")
    if args.letters is not None and not args.letters.strip():
        raise ValueError("--letters needs some text to press, got none")
    if args.grip is not None and (chosen or part.axis is None):
        where = f"--{chosen[0]} presses" if chosen else f"the {part.name} has no limb to grasp"
        raise ValueError(f"--grip chooses how the hand grasps a limb; {where}: leave it out")
    if len(chosen) > 1:
        raise ValueError(f"choose one object, got {', '.join('--' + k for k in chosen)}")
    if args.pose is not None and chosen[:1] not in (["object"], ["sphere"], ["letters"]):
        raise ValueError("--pose places an --object, --sphere or --letters")
    if args.given == "pose" and (args.strap or (not chosen and part.axis is None)):
        raise ValueError(
            "--given pose presses an --object, --sphere or --letters where it is put, or closes "
            "the hand's grasp round a limb (a strap or the open hand has no pose to press to)"
        )
    if args.strap:
        return [objects.strap(part, args.along, total=args.force, squeeze=args.depth * mm)]
    if chosen:
        k = chosen[0]
        mesh = (
            contact.read_mesh(args.object)
            if k == "object"
            else objects.sphere(args.sphere * mm)
            if k == "sphere"
            else objects.letters(args.letters)
        )
        name = (
            pathlib.Path(args.object).stem
            if k == "object"
            else (f"sphere {args.sphere:g} mm" if k == "sphere" else f"letters {args.letters}")
        )
        if k == "object" and not mesh.is_watertight:
            print(
                f"note: {pathlib.Path(args.object).name} is not watertight; what lies inside it "
                "is judged by its nearest faces' normals"
            )
        if args.pose is not None:
            pose = contact.pose_matrix(np.asarray(args.pose[:3]) * mm, args.pose[3:])
        else:
            pose = objects.press(
                part, mesh, uv=tuple(args.at), depth=args.depth * mm, spin=args.spin
            )
        return [contact.Pressing(mesh, pose, args.force, name)]

    hand = {"height": args.hand_height}
    if part.axis is None:  # nothing to grasp around: the open hand laid on the skin
        return [
            palm_press(
                part,
                Hand(phenotype=hand),
                tuple(args.at),
                args.depth * mm,
                np.pi / 2 + args.spin,
                args.force,
            )
        ]
    kind = args.grip or "whole"
    g = cached_grasp(part, hand, args.along, args.around, kind, args.depth * mm)
    short = [f if f == "thumb" else f"{f} finger" for f in GRIPS[kind] if f not in g.reached]
    if short:
        print(
            f"note: the {kind} grip's {' and '.join(short)} cannot curl {args.depth:g} mm into "
            f"the limb at {args.along:g} along: {'they carry' if len(short) > 1 else 'it carries'}"
            " only what it touches (try another --along or --grip)"
        )
    return [g.pressing(args.force, f"right hand ({kind})")]


def grasping(args, part) -> bool:
    """Whether the options grasp the limb with anny's hand (no object, strap or open hand)."""
    chosen = any(getattr(args, k) is not None for k in ("object", "sphere", "letters"))
    return not chosen and not args.strap and part.axis is not None


WAYS = {"force": "a force on the skin", "pose": "an object's pose"}
"""How a scene can be given, as the command line says it."""


def given_of(given: str | None, specs: list[str], preds: list) -> str:
    """How the scene is given (``--given``): as asked, else as the models take it (an object's
    pose for models trained on pressed objects; the FEM takes either), else by force. Models
    that take it only the other way, or only in different ways, are refused by name.
    """
    only = {spec: p.takes[0] for spec, p in zip(specs, preds) if len(p.takes) == 1}
    ways = set(only.values())
    if len(ways) > 1:
        by = "; ".join(f"{spec} {WAYS[way]}" for spec, way in only.items())
        raise ValueError(f"the models take different scenes ({by}): compare each apart")
    if given is not None:
        wrong = [spec for spec, way in only.items() if way != given]
        if wrong:
            way = only[wrong[0]]
            raise ValueError(
                f"--given {given}, and {', '.join(wrong)} takes only {WAYS[way]}: use "
                f"--given {way} (or leave it out)"
            )
        return given
    return ways.pop() if ways else "force"


def models_of(args) -> list[str]:
    """The models asked, else the default: the grip model of real tissue for anny's hand on her
    left forearm (at the tissue it learned, with its squeeze unless ``--force`` is given, the
    FEM beside it on its data's mesh unless ``--res`` is), else the part's model of the paper's
    gel. Sets ``args.tissue``, ``args.force`` and ``args.res`` where it chose.
    """
    if args.model:
        return args.model
    hand = not any(getattr(args, k) is not None for k in ("object", "sphere", "letters"))
    if hand and not args.strap and args.part == "left_arm" and args.tissue in (None, GRASP_TISSUE):
        other = {k: v for k, v in phenotype_of(args).items() if v != 0.5}
        if other:
            said = " ".join(f"--{k} {v:g}" for k, v in other.items())
            raise ValueError(
                f"the grip model of real tissue ({GRASP_MODEL}) knows anny's default body, not "
                f"{said}: add --tissue paper (the models of every body, on the paper's gel) or "
                f"--model fem --tissue {GRASP_TISSUE} (the FEM, an hour or more a grasp)"
            )
        args.tissue = GRASP_TISSUE
        if not args.force_given:
            args.force, args.force_given = GRASP_FORCE_N, True
        if not args.res_given:  # the FEM beside it as the model's data was solved
            args.res = GRASP_RESOLUTION
        return [GRASP_MODEL]
    return [default_model(args.part)]


def run(args) -> int:
    """``stmpl simulate``: build the scene, predict, compare, write and print."""
    t0 = time.perf_counter()
    specs = models_of(args)
    preds = answers.predictors(args, specs)
    args.given = given_of(args.given, specs, preds)
    sub = answers.skin_of(preds, args.subdivide, 1)  # the FEM alone: the once-subdivided skin
    part = part_from_spec(
        {"model": "anny", "subdivisions": sub, "phenotype": phenotype_of(args)}, args.part
    )
    objs = pressings(args, part)
    thick = thickness_of(args, part)
    drawn = [o.posed() for o in objs]
    force = args.force if args.given == "pose" and args.force_given else None
    if args.given == "pose" and grasping(args, part):
        kind = args.grip or "whole"
        hand = {"height": args.hand_height}  # the body whose right hand grips: kept on disk
        scene = gripped(part, thick, args.depth * 1e-3, hand, args.along, args.around, kind)
        drawn = [_mesh(scene.pose.objects[0])]
        said = (
            f"right hand ({kind}) closed {args.depth:g} mm from first touch, "
            f"{scene.pose.nearest()} "
            + (
                "(the squeeze it meets is answered)"
                if force is None
                else f"(then closed until its squeeze is {force:g} N)"
            )
        )
    elif args.given == "pose":
        scene = posed(part, thick, [(o.mesh, o.pose, o.name) for o in objs])
        said = f"{objs[0].name} at its pose, {scene.pose.nearest()} " + (
            "(the force it meets is answered)"
            if force is None
            else f"(then pressed until it meets {force:g} N)"
        )
    else:
        touch = contact.contact(part, objs)
        scene = Scene.from_load(part, thick, touch.load())
        said = touch.summary()
    print(
        f"{part.name} ({part.n_vertices} vertices), {1e3 * float(thick.mean()):.3g} mm of "
        f"{answers.tissue_words(args.tissue)}; {said}  [{time.perf_counter() - t0:.1f} s to set up]"
    )
    out = answers.answer(scene, specs, preds, args.strict, force)
    failures: dict = {}
    fem = answers.truth(scene, args, failures, force) if args.compare else None
    if force is not None:  # the objects where the first answer pressed them
        drawn = [_mesh(o) for o in next(iter(out.values())).scene.pose.objects]
    if fem is not None:
        answers.errors(out, fem)
    folder = pathlib.Path(args.out_dir)
    folder.mkdir(parents=True, exist_ok=True)
    name, first = next(iter(out.items()))
    write_meshes(first, drawn, folder / "pressed", facts(first, name))
    contact_figure(
        out,
        fem,
        drawn,
        folder / "simulate.png",
        failed=failures,
        tissue=answers.tissue_words(args.tissue),
    )
    atomic_write_text(
        folder / "simulate.json", json.dumps(answers.record(out, fem, failures), indent=1)
    )
    print(
        f"wrote {folder / 'pressed.glb'} (body and object), {folder / 'pressed.ply'}, "
        f"{folder / 'simulate.png'}, {folder / 'simulate.json'} (every answer and failure)"
    )
    return 0


def _mesh(rigid) -> Mesh:
    """A posed object (:class:`~stmpl.pose.Rigid`) as a mesh to draw."""
    return Mesh(rigid.vertices, rigid.faces)


def write_meshes(deformation, objects, base, about: dict | None = None) -> None:
    """``base.glb``: the deformed part coloured by |u| with the objects (meshes in body
    coordinates) in place, see-through; ``base.ply``: the deformed part alone; both carry
    ``about`` (:func:`stmpl.viz.verdict.facts`).
    """
    part, mag = deformation.scene.part, deformation.magnitude
    export_mesh(
        part, pathlib.Path(base).with_suffix(".ply"), mag, deformation.vertices, facts=about
    )
    body = {
        "name": "body",
        "vertices": deformation.vertices,
        "faces": part.faces,
        "colors": vertex_colors(mag),
    }
    drawn = [
        {"name": f"object{k}", "vertices": m.vertices, "faces": m.faces, "color": OBJECT_COLOR}
        for k, m in enumerate(objects)
    ]
    pathlib.Path(base).with_suffix(".glb").write_bytes(glb_bytes([body, *drawn], glb_extras(about)))


OBJECT_COLOR = (150, 190, 255, 120)
"""RGBA of the pressing objects in the GLB: light blue, see-through."""
