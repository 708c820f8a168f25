"""The ``stmpl`` commands of the core: each takes the parsed options and returns an exit code.

The main job, ``stmpl simulate``, has its own module (:mod:`stmpl.cli.simulate`); the FEM adds
``generate`` and ``solve`` (:mod:`fem.commands`) through entry points.
"""

from __future__ import annotations

import time

from stmpl.analysis import limits
from stmpl.analysis.ablation import run as run_ablation
from stmpl.cli import answers
from stmpl.cli.arguments import default_model
from stmpl.cli.options import body_of, phenotype_of, scene_of
from stmpl.data.dataset import open_data
from stmpl.pipeline import zoo
from stmpl.pipeline.evaluate import evaluate
from stmpl.pipeline.spec import predictor_from_spec
from stmpl.pipeline.train import train
from stmpl.viewer.app import Viewer
from stmpl.viz.figures import export_mesh, prediction_figure, scene_figure


def scene(args) -> int:
    """``stmpl scene``: build a primitive scene, draw it, save it, export its mesh."""
    s = scene_of(args)
    if args.out:
        scene_figure(s, args.out, size=args.size)
        print(f"wrote {args.out}")
    if args.save:
        s.save(args.save)
        print(f"wrote {args.save}")
    if args.export:
        export_mesh(s.part, args.export, s.force)
        print(f"wrote {args.export}")
    return 0


def predict(args) -> int:
    """``stmpl predict``: a primitive scene answered by models (and with ``--compare`` the
    FEM), on the skin the first model was trained on.
    """
    specs = args.model or [default_model(args.part)]
    preds = answers.predictors(args, specs)
    s = scene_of(args, answers.skin_of(preds, args.subdivide, 0))
    out = answers.answer(s, specs, preds, args.strict)
    fem = answers.truth(s, args) if args.compare else None
    if fem is not None:
        answers.errors(out, fem)
    if args.out:
        prediction_figure(out, fem, args.out)
        print(f"wrote {args.out}")
    if args.save:
        if len(out) != 1:
            raise ValueError("--save takes one --model")
        next(iter(out.values())).save(args.save)
        print(f"wrote {args.save}")
    return 0


def view(args) -> int:
    """``stmpl view``: serve the viewer until Ctrl-C."""
    models = args.model or [
        default_model(args.part),
        *(["zoo:linear_arm_fine", "zoo:naive_arm_fine"] if args.part.endswith("_arm") else []),
    ]
    phenotype = phenotype_of(args)
    print(f"loading {', '.join(models)} and anny's {args.part}...")
    v = Viewer(
        models,
        args.part,
        phenotype,
        args.thickness,
        host=args.host,
        port=args.port,
        device=args.device,
        fidelity=args.fidelity,
        prepare=args.prepare,
    )
    print(
        f"stmpl view: open http://{args.host}:{v.server.get_port()} in your browser (Ctrl-C ends)"
    )
    try:
        while True:
            time.sleep(3600)
    except KeyboardInterrupt:
        print("stopped")
    finally:
        v.close()
    return 0


def train_model(args) -> int:
    """``stmpl train``: train (or resume) a config's model."""
    path = train(args.config, resume=not args.restart, progress=not args.quiet)
    print(f"wrote {path}")
    return 0


def ablate(args) -> int:
    """``stmpl ablate``: the paper's tables (or a stability sweep) from a config."""
    res = run_ablation(args.config, progress=not args.quiet, accept_remade=args.accept_remade)
    if "points" in res and "tables" not in res:
        print(f"wrote {res['out'] / 'stability.md'}, one picture per axis and the envelope map")
    else:
        print(f"wrote {res['out'] / 'ablation.md'}, the tables (.md, .csv) and the chart")
    return 0


def evaluate_models(args) -> int:
    """``stmpl evaluate``: predictors measured on a dataset split."""
    ds = open_data(args.data)  # one folder, or several read as one
    predictors = {
        spec: predictor_from_spec(spec, args.device, fidelity=args.fidelity)
        for spec in args.predictors
    }
    print(evaluate(predictors, ds, args.split, args.out, args.limit, args.to_force), end="")
    if args.out:
        print(f"wrote {args.out} (.md, .csv)")
    return 0


def zoo_models(args) -> int:
    """``stmpl zoo verify|add|measure|limit|support`` (``list`` and ``show``:
    :mod:`stmpl.cli.zoo`).
    """
    if args.action == "verify":
        bad = []
        for name in args.names or zoo.names(args.zoo):
            try:
                f = zoo.verify(name, args.zoo)
            except (ValueError, OSError, LookupError) as e:
                print(f"{name}: FAILED: {e}")
                bad.append(name)
                continue
            print(f"{name}: {f.name} ok")
        if bad:
            raise ValueError(f"{len(bad)} zoo model(s) failed verification: {', '.join(bad)}")
    elif args.action == "limit":
        if not args.sweep:
            raise ValueError("zoo limit needs --sweep CONFIG (a stability sweep that has run)")
        limits.cap_zoo(args.names, args.sweep, path=args.zoo)
    elif args.action == "support":
        if not args.trained_on:
            raise ValueError("zoo support needs --trained-on DATA [DATA ...]")
        zoo.support(args.names, args.trained_on, args.zoo)
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
        e = zoo.add(args.checkpoint, args.names[0], trained, args.zoo, args.evaluate_on, args.force)
        print(f"added {args.names[0]}: {e['file']} ({e['bytes'] / 1e6:.2f} MB)")
    return 0


def parts(args) -> int:
    """``stmpl parts``: the body model's parts and their sizes."""
    body = body_of(args)
    print(f"{'part':<12}{'vertices':>10}{'faces':>8}{'seam':>6}{'rims':>6}  chart m/unit")
    for name in body.part_names():
        p = body.part(name)
        print(
            f"{name:<12}{p.n_vertices:>10}{p.n_faces:>8}{len(p.seam_vertices):>6}"
            f"{len(p.rims):>6}  {p.uv_scale:.3f}"
        )
    return 0
