"""The ``stmpl`` command line."""

from __future__ import annotations

import argparse
import logging
import re
import sys
import traceback
import warnings
from importlib.metadata import entry_points

import numpy as np

from stmpl import loads, predictor, tissue
from stmpl.analysis import limits
from stmpl.analysis.ablation import run
from stmpl.body.anny_body import phenotype_of, phenotype_options
from stmpl.body.smpl_body import smpl_options
from stmpl.body.spec import body_from_spec
from stmpl.cli import simulate
from stmpl.cli.simulate import DEFAULT_MODEL, default_model
from stmpl.data.dataset import open_data
from stmpl.pipeline import zoo
from stmpl.pipeline.evaluate import evaluate
from stmpl.pipeline.spec import label, predictor_from_spec
from stmpl.pipeline.train import train
from stmpl.predictor import PredictionFailed, create
from stmpl.scene import Scene
from stmpl.viz.figures import deformation_figure, export_mesh, prediction_figure, scene_figure

log = logging.getLogger("stmpl")

COMMANDS = "stmpl.commands"
"""Entry-point group of commands other packages add: a function taking the subparsers."""


def _body_spec(args) -> dict:
    """The body spec (:mod:`stmpl.body.spec`) the command-line options describe."""
    if args.smpl:
        return {
            "model": "smpl",
            "path": args.smpl,
            "uv_path": args.smpl_uv,
            "betas": [0.0, args.beta2] if args.beta2 is not None else None,
        }
    return {"model": "anny", "phenotype": phenotype_of(args)}


def _body(args):

    return body_from_spec(_body_spec(args))


def _thickness(args, body, part):

    if args.thickness is not None:
        return tissue.constant(part, args.thickness * 1e-3)
    if args.smpl:
        return tissue.from_beta2(part, args.beta2 or 0.0)
    return tissue.from_weight(part, args.weight)


def _load(args, part):

    total = args.force
    at = {"uv": tuple(args.at)} if args.at else {"uv": (0.5, 0.5)}
    mm = 1e-3
    if args.load == "disk":
        return loads.disk(part, radius=args.radius * mm, total=total, **at)
    if args.load == "ellipse":
        return loads.ellipse(
            part,
            semi_axes=(args.radius * mm, args.radius * mm / 2),
            angle=args.angle,
            total=total,
            **at,
        )
    if args.load == "seam_disk":
        return loads.seam_disk(part, args.along, args.radius * mm, total)
    if args.load == "spots":
        return loads.spots(
            part,
            count=args.count,
            radius=args.radius * mm,
            spread=args.spread * mm,
            total=total,
            **at,
        )
    if args.load == "band":
        return loads.band(part, args.along, args.width * mm, total)
    return loads.letter(
        part, args.char, at["uv"], args.char_height * mm, args.width * mm, args.angle, total
    )


def cmd_train(args) -> int:

    path = train(args.config, resume=not args.restart, progress=not args.quiet)
    print(f"wrote {path}")
    return 0


def cmd_ablate(args) -> int:

    res = run(args.config, progress=not args.quiet, accept_remade=args.accept_remade)
    if "points" in res and "tables" not in res:
        print(f"wrote {res['out'] / 'stability.md'}, one picture per axis and the envelope map")
    else:
        print(f"wrote {res['out'] / 'ablation.md'}, the tables (.md, .csv) and the chart")
    return 0


def cmd_evaluate(args) -> int:

    ds = open_data(args.data)
    predictors = {
        spec: predictor_from_spec(spec, args.device, fidelity=args.fidelity)
        for spec in args.predictors
    }
    print(evaluate(predictors, ds, args.split, args.out, args.limit), end="")
    if args.out:
        print(f"wrote {args.out} (.md, .csv)")
    return 0


def cmd_zoo(args) -> int:
    if args.action == "list":
        print(zoo.table(args.zoo), end="")
    elif args.action == "verify":
        for name in args.names or zoo.names(args.zoo):
            f = zoo.verify(name, args.zoo)
            print(f"{name}: {f.name} ok")
    elif args.action == "limit":
        if not args.sweep:
            raise ValueError("zoo limit needs --sweep CONFIG (a stability sweep that has run)")
        limits.cap_zoo(args.names, args.sweep, path=args.zoo)
    elif args.action == "measure":
        if not args.evaluate_on:
            raise ValueError("zoo measure needs --evaluate-on DATA [DATA ...]")
        zoo.measure(args.names, args.evaluate_on, args.zoo)
    else:  # add
        if not args.checkpoint or len(args.names) != 1:
            raise ValueError("zoo add needs --checkpoint FILE and one NAME")
        trained = (
            {"command": args.command_line, "machine": args.machine, "time": args.time}
            if args.command_line
            else None
        )
        e = zoo.add(args.checkpoint, args.names[0], trained, args.zoo, args.evaluate_on)
        print(f"added {args.names[0]}: {e['file']} ({e['bytes'] / 1e6:.2f} MB)")
    return 0


def cmd_scene(args) -> int:

    scene = _scene(args)
    part = scene.part
    if args.out:
        scene_figure(scene, args.out, size=args.size)
        print(f"wrote {args.out}")
    if args.save:
        scene.save(args.save)
        print(f"wrote {args.save}")
    if args.export:
        export_mesh(part, args.export, scene.force)
        print(f"wrote {args.export}")
    return 0


def _scene(args, subdivisions: int = 0):
    """The scene the command-line options describe (its load summary printed), on the part
    subdivided ``subdivisions`` times.
    """
    body = _body(args)
    part = body.part(args.part).subdivided(subdivisions)
    load = _load(args, part)
    print(load.summary())
    return Scene.from_load(part, _thickness(args, body, part), load, body=body.name)


def cmd_solve(args) -> int:

    scene = _scene(args)
    fem = predictor.create("fem", res=args.res, levels=args.levels)
    d = fem.predict(scene)  # a failed solve raises, naming the reason
    shell = fem.last_shell
    print(
        f"shell: {d.info['mesh']['nodes']} nodes, {d.info['mesh']['tets']} tets ({args.res}); "
        f"{shell.mesh.quality()}"
    )
    for s in d.info["levels"]:
        print(
            f"  {s['total_force']:6.3f} N  ok  {s['iterations']} Newton steps  "
            f"max |u| {1e3 * s['max_displacement']:.2f} mm  {s['time']:.2f} s"
        )
    if args.out:
        deformation_figure(
            d, shell.mesh.nodes, shell.mesh.tets, shell.displacement, args.out, size=args.size
        )
        print(f"wrote {args.out}")
    if args.save:
        d.save(args.save)
        print(f"wrote {args.save}")
    if args.vtu:
        shell.mesh.to_vtu(args.vtu, point_data={"displacement": shell.displacement})
        print(f"wrote {args.vtu}")
    return 0


def cmd_predict(args) -> int:

    specs = args.model or [default_model(args.part)]
    preds = [predictor_from_spec(spec, args.device, fidelity=args.fidelity) for spec in specs]
    sub = args.subdivide
    if sub is None:  # the surface the first model was trained on, else the FEM's plain arm
        sub = next(
            (
                int(p.part.source.get("subdivisions", 0))
                for p in preds
                if getattr(p, "part", None) is not None
            ),
            0,
        )
    scene = _scene(args, sub)
    out = {}
    for spec, p in zip(specs, preds):
        d = p.predict(scene)
        name = label(spec)
        out[name] = d
        print(
            f"{name:<24} max |u| {1e3 * d.magnitude.max():6.3f} mm  "
            f"{1e3 * d.info['seconds']:8.2f} ms"
        )
    truth = None
    if args.compare:
        try:
            truth = create("fem", res=args.res, levels=args.levels).predict(scene)
        except PredictionFailed as e:  # the models' answers stand; the FEM's failure is said
            print(f"{'fem (' + args.res + ')':<24} failed: {e}; no errors to show")
    if truth is not None:
        print(
            f"{'fem (' + args.res + ')':<24} max |u| {1e3 * truth.magnitude.max():6.3f} mm  "
            f"{1e3 * truth.info['seconds']:8.2f} ms"
        )
        active = truth.magnitude * 1e3 > 0.001
        for name, d in out.items():
            err = np.linalg.norm(d.displacement - truth.displacement, axis=1)[active] * 1e3
            rel = 100 * err.mean() / (1e3 * truth.magnitude.max())
            print(
                f"  {name}: MEE {err.mean():.4f} mm = {rel:.2f} % of the max, max error "
                f"{err.max():.3f} mm"
            )
    if args.out:
        prediction_figure(out, truth, args.out)
        print(f"wrote {args.out}")
    if args.save:
        if len(out) != 1:
            raise ValueError("--save takes one --model")
        next(iter(out.values())).save(args.save)
        print(f"wrote {args.save}")
    return 0


def cmd_parts(args) -> int:
    body = _body(args)
    print(f"{'part':<12}{'vertices':>10}{'faces':>8}{'seam':>6}{'rims':>6}  chart m/unit")
    for name in body.part_names():
        p = body.part(name)
        print(
            f"{name:<12}{p.n_vertices:>10}{p.n_faces:>8}{len(p.seam_vertices):>6}"
            f"{len(p.rims):>6}  {p.uv_scale:.3f}"
        )
    return 0


def _positive(text: str) -> int:
    """An argparse type: an integer >= 1."""
    try:
        n = int(text)
    except ValueError:
        n = 0
    if n < 1:
        raise argparse.ArgumentTypeError(f"must be an integer >= 1, got {text!r}")
    return n


def device(text: str) -> str:
    """An argparse type: a torch device this machine has (``cpu``, ``cuda``, ``cuda:N``,
    ``mps``).
    """
    if not re.fullmatch(r"cpu|cuda(:[0-9]+)?|mps", text):
        raise argparse.ArgumentTypeError(f"unknown device {text!r}; use cpu, cuda, cuda:N or mps")
    if text != "cpu":
        import torch  # deferred: about a second to import; the core's types do not need it

        ok = (
            torch.backends.mps.is_available()
            if text == "mps"
            else (
                torch.cuda.is_available()
                and int(text.partition(":")[2] or 0) < torch.cuda.device_count()
            )
        )
        if not ok:
            raise argparse.ArgumentTypeError(f"device {text} is not available on this machine")
    return text


def _body_args(p) -> None:
    phenotype_options(p)
    smpl_options(p)


def _scene_args(sc, force: float) -> None:
    _body_args(sc)
    sc.add_argument("--part", default="left_arm", help="body part (default left_arm)")
    sc.add_argument(
        "--load",
        default="disk",
        choices=["disk", "ellipse", "seam_disk", "spots", "band", "letter"],
    )
    sc.add_argument(
        "--force", type=float, default=force, help=f"total force F_total, N (default {force:g})"
    )
    sc.add_argument("--radius", type=float, default=20.0, help="disk, spot radius / ellipse a, mm")
    sc.add_argument("--count", type=int, default=3, help="number of spots (default 3)")
    sc.add_argument("--spread", type=float, default=40.0, help="spots' spread, mm (default 40)")
    sc.add_argument("--width", type=float, default=30.0, help="band width / letter stroke, mm")
    sc.add_argument("--char-height", type=float, default=100.0, help="letter height, mm")
    sc.add_argument("--char", default="A", help="letter character")
    sc.add_argument("--angle", type=float, default=0.0, help="ellipse/letter angle, rad")
    sc.add_argument(
        "--along",
        type=float,
        default=0.5,
        help="band/seam disk position along the limb or seam, 0..1",
    )
    sc.add_argument(
        "--at",
        type=float,
        nargs=2,
        metavar=("U", "V"),
        help="load centre in chart coordinates (default 0.5 0.5)",
    )
    sc.add_argument("--thickness", type=float, help="constant thickness, mm (default: heuristic)")
    sc.add_argument("--size", type=int, default=256, help="UV image size in the picture, px")


def parser() -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(
        prog="stmpl",
        description="Soft-tissue contact deformation of "
        "human bodies: scenes, FEM ground truth, learned predictors.",
    )
    ap.add_argument("-v", "--verbose", action="store_true", help="log progress")
    sub = ap.add_subparsers(dest="command", required=True)

    sc = sub.add_parser("scene", help="build a loaded scene on a body part and draw it")
    _scene_args(sc, force=5.0)
    sc.add_argument("--out", help="PNG picture to write")
    sc.add_argument("--save", help="scene file to write (.npz)")
    sc.add_argument("--export", help="mesh coloured by force to write (.ply/.obj/.glb)")
    sc.set_defaults(func=cmd_scene)

    sm = sub.add_parser(
        "simulate",
        help="the main job: an object (by default anny's right hand) "
        "pressed on the body, predicted (and with --compare solved by the FEM); "
        "writes the deformed body and a picture",
    )
    simulate.add_arguments(sm)
    sm.set_defaults(func=simulate.run)

    si = sub.add_parser("solve", help="solve a primitive load with the FEM and draw its section")
    _scene_args(si, force=0.3)
    si.add_argument("--levels", type=int, default=3, help="continuation levels up to --force")
    si.add_argument(
        "--res",
        default="reference",
        help="mesh resolution: coarse, medium, fine, finest or reference",
    )
    si.add_argument("--out", help="PNG picture to write")
    si.add_argument("--save", help="deformation file to write (.npz)")
    si.add_argument("--vtu", help="the deformed tissue shell for ParaView (.vtu)")
    si.set_defaults(func=cmd_solve)

    pr = sub.add_parser(
        "predict",
        help="predict a loaded scene with learned models (zoo or "
        "checkpoint) and draw it; --compare solves the FEM beside them",
    )
    _scene_args(pr, force=0.3)
    pr.add_argument(
        "--model",
        action="append",
        help=f"zoo:<name>, a .safetensors checkpoint "
        f"or fem[:res]; repeat to compare (default {DEFAULT_MODEL})",
    )
    pr.add_argument(
        "--subdivide",
        type=int,
        default=None,
        metavar="N",
        help="the skin's resolution: the part's triangles split into four N times "
        "(default: the first model's own, 1 for the shipped models)",
    )
    pr.add_argument("--compare", action="store_true", help="also solve the FEM and report errors")
    pr.add_argument("--res", default="reference", help="FEM resolution for --compare")
    pr.add_argument("--levels", type=int, default=3, help="FEM continuation levels (--compare)")
    pr.add_argument(
        "--device", default="cpu", type=device, help="torch device for learned models (default cpu)"
    )
    pr.add_argument(
        "--fidelity",
        default="full",
        choices=["full", "auto"],
        help="full: model the whole part; auto: only what the scene needs (the GNN "
        "on the subgraph around the load, the FEM on the patch it moves)",
    )
    pr.add_argument("--out", help="PNG picture to write")
    pr.add_argument("--save", help="deformation file to write (.npz)")
    pr.set_defaults(func=cmd_predict)

    tr = sub.add_parser("train", help="train a learned predictor from a config (resumable)")
    tr.add_argument("config", help="training config (YAML), e.g. configs/train/naive.yaml")
    tr.add_argument("--restart", action="store_true", help="ignore a saved state; start over")
    tr.add_argument("--quiet", action="store_true", help="no progress bar")
    tr.set_defaults(func=cmd_train)

    ev = sub.add_parser("evaluate", help="measure predictors on a dataset split")
    ev.add_argument(
        "predictors",
        nargs="+",
        help="fem, fem:<resolution>, zoo:<name>, or .safetensors checkpoints",
    )
    ev.add_argument("--data", required=True, help="dataset folder")
    ev.add_argument("--split", default="test", choices=["train", "val", "test"])
    ev.add_argument("--limit", type=_positive, help="first N samples only")
    ev.add_argument(
        "--device", default="cpu", type=device, help="torch device for learned models (default cpu)"
    )
    ev.add_argument(
        "--fidelity",
        default="full",
        choices=["full", "auto"],
        help="full: model the whole part; auto: only what the scene needs (the GNN "
        "on the subgraph around the load, the FEM on the patch it moves)",
    )
    ev.add_argument("--out", help="write the table here (.md and .csv)")
    ev.set_defaults(func=cmd_evaluate)

    ab = sub.add_parser(
        "ablate",
        help="the paper's Tables 1-3 for every predictor: trains or "
        "takes the set-ups, evaluates, writes the report (cached, resumable)",
    )
    ab.add_argument("config", help="ablation config (YAML), e.g. configs/ablation/small.yaml")
    ab.add_argument("--quiet", action="store_true", help="no progress bar")
    ab.add_argument(
        "--accept-remade",
        action="store_true",
        help="a dataset made again whose content hash changed: keep the cached "
        "results if a cached set-up measures the same on it",
    )
    ab.set_defaults(func=cmd_ablate)

    zo = sub.add_parser(
        "zoo", help="the shipped models: list, verify, add, measure on more datasets"
    )
    zo.add_argument("action", choices=["list", "verify", "add", "measure", "limit"])
    zo.add_argument("names", nargs="*", help="model names (verify, measure: default all; add: one)")
    zo.add_argument("--zoo", help="zoo folder (default $STMPL_ZOO or the repository's zoo/)")
    zo.add_argument("--checkpoint", help="add: the .safetensors checkpoint to add")
    zo.add_argument("--command-line", help="add: the command that trained it")
    zo.add_argument("--machine", help="add: the machine it trained on")
    zo.add_argument("--time", help="add: how long it trained")
    zo.add_argument(
        "--evaluate-on",
        nargs="+",
        metavar="DATA",
        help="add, measure: measure these datasets' test splits (e.g. data/ood_grasps)",
    )
    zo.add_argument(
        "--sweep",
        metavar="CONFIG",
        help="limit: the stability sweep whose points cap the models' envelopes "
        "where they break their promise (configs/ablation/stability.yaml)",
    )
    zo.set_defaults(func=cmd_zoo)

    pa = sub.add_parser("parts", help="list the body model's parts and their sizes")
    _body_args(pa)
    pa.set_defaults(func=cmd_parts)
    for ep in sorted(entry_points(group=COMMANDS), key=lambda e: e.name):
        ep.load()(sub)  # e.g. `generate`, from the fem package
    return ap


def _expected() -> tuple:

    return (ValueError, OSError, LookupError, PredictionFailed)


# Failures a user can act on (bad input, a missing or unwritable file, an unknown name, a failed
# solve, an unusable device) end with one line on stderr and exit code 2; ``-v`` adds the
# traceback. Anything else is a bug and keeps its traceback.


def _message(exc: BaseException) -> str:
    """One line naming the problem: the exception's own text (a file error with its path)."""
    if isinstance(exc, OSError) and exc.filename is not None and exc.strerror:
        text = f"{exc.strerror}: {exc.filename}"
    elif isinstance(exc, KeyError) and exc.args:
        text = str(exc.args[0])
    else:
        text = str(exc) or type(exc).__name__
    return " ".join(text.split())


def main(argv=None) -> int:
    args = parser().parse_args(argv)
    logging.basicConfig(
        level=logging.INFO if args.verbose else logging.WARNING,
        format="%(levelname)s %(name)s: %(message)s",
    )

    def one_line(message, *_, **__):  # a warning is one line, like an error
        print(f"stmpl {args.command}: warning: {message}", file=sys.stderr)

    try:
        with warnings.catch_warnings():
            if not args.verbose:
                warnings.showwarning = one_line
            return args.func(args)
    except _expected() as exc:
        if args.verbose:
            traceback.print_exc()
        print(f"stmpl {args.command}: error: {_message(exc)}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
