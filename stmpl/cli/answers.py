"""One runner for the commands that answer a scene (``stmpl predict`` and ``stmpl simulate``):
each predictor answers it (its time that of a second, warm call), each answer says where it
stands (outside its data, physically impossible), and with ``--compare`` the FEM solves it and
each answer is measured against it (:func:`stmpl.metrics.sample_metrics`).
"""

from __future__ import annotations

import time
import warnings

from stmpl import predictor
from stmpl.cli import kept
from stmpl.cli.arguments import TISSUE
from stmpl.cli.options import phenotype_of
from stmpl.contact.force_control import to_force
from stmpl.metrics import sample_metrics
from stmpl.pipeline.spec import label, predictor_from_spec
from stmpl.predictor import ImpossibleAnswer, OutsideEnvelope, PredictionFailed
from stmpl.viz.render import duration
from stmpl.viz.verdict import impossible

WIDTH = 20
"""Characters of the name column."""


def predictors(args, specs: list[str]) -> list:
    """The predictors ``specs`` name, at the options' device, fidelity and FEM set-up. The
    tissue (``args.tissue``, set here when not given) is the one asked, else the first learned
    model's (the FEM alone: the paper's gel); a learned model of another tissue is refused by
    name: it would answer its own tissue's dent for the tissue asked.
    """

    def made(spec, tissue="paper"):
        return predictor_from_spec(
            spec,
            args.device,
            res=args.res,
            levels=args.levels,
            fidelity=args.fidelity,
            tissue=tissue,
            phenotype=phenotype_of(args),
            friction=args.friction,
            engine=getattr(args, "engine", "default"),
        )

    fem = [spec == "fem" or spec.startswith("fem:") for spec in specs]
    learned = {spec: made(spec) for spec, f in zip(specs, fem) if not f}
    tissue = args.tissue or next((p.tissue for p in learned.values()), TISSUE)
    for spec, p in learned.items():
        if p.tissue != tissue:
            raise ValueError(
                f"{label(spec)} learned {_tissue(p.tissue)}, and --tissue asks for "
                f"{_tissue(tissue)}: it would answer the dent of its own; choose a model of "
                f"that tissue, or --model fem --tissue {tissue}"
            )
    args.tissue = tissue
    if args.friction is None:  # the FEM meets the objects as the learned models' data did
        had = [p.friction for p in learned.values() if p.friction is not None]
        args.friction = had[0] if had else 0.0
    return [made(spec, tissue) if f else learned[spec] for spec, f in zip(specs, fem)]


def _tissue(name: str) -> str:
    """A tissue in words: the paper's gel or a preset (or a file of layers) by name."""
    return "the paper's 1 kPa gel" if name == TISSUE else f"the {name} tissue"


def tissue_words(name: str) -> str:
    """What a scene's thickness is of, in words: the paper's gel, or a layered tissue's skin
    and fat over its muscle.
    """
    return _tissue(name) if name == TISSUE else f"skin and fat ({_tissue(name)}, over its muscle)"


def skin_of(preds: list, asked: int | None, default: int) -> int:
    """How often the part is subdivided: as ``asked``, else the surface the first learned
    model was trained on, else ``default``.
    """
    if asked is not None:
        return asked
    return next(
        (
            int(p.part.source.get("subdivisions", 0))
            for p in preds
            if getattr(p, "part", None) is not None
        ),
        default,
    )


def answer(scene, specs: list[str], preds: list, strict: bool = False, force=None) -> dict:
    """``{label: Deformation}``: every predictor's answer to ``scene``, printed one line each
    with a note where it lies outside its data or is impossible. ``strict``: such a scene or
    answer raises :class:`PredictionFailed` instead. ``force`` (N): a posed scene's objects
    pressed from their pose until each predictor's answer meets it
    (:func:`stmpl.contact.force_control.to_force`).
    """
    out = {}
    for spec, p in zip(specs, preds):
        if strict:
            why = p.outside([scene])[0]
            if why:
                raise PredictionFailed(
                    f"{label(spec)}: the scene lies outside the data its answers are backed "
                    f"by ({'; '.join(why)}); --strict refuses it"
                )
        first = None
        with warnings.catch_warnings():  # said in the lines below instead
            warnings.simplefilter("ignore", ImpossibleAnswer)
            warnings.simplefilter("ignore", OutsideEnvelope)
            if force is not None:  # the search's first answers warm it up
                out[label(spec)] = d = to_force(p, scene, force)
            else:
                if getattr(p, "batched", True):  # a learned model: warm up, first call apart
                    t0 = time.perf_counter()
                    p.predict(scene)
                    first = time.perf_counter() - t0
                    if hasattr(p, "forget_scenes"):  # timed as a new scene, not a repeat
                        p.forget_scenes()
                out[label(spec)] = d = p.predict(scene)
        if strict and not d.info.get("physical", True):
            raise PredictionFailed(
                f"{label(spec)}: {'; '.join(impossible(d.info))}; --strict refuses the answer"
            )
        _say(label(spec), p, d, first)
    return out


def _say(name: str, p, d, first: float | None) -> None:
    slow = first is not None and first > max(0.2, 20 * d.info["seconds"])
    line = f"{name:<{WIDTH}} deepest {1e3 * d.magnitude.max():6.3f} mm  "
    line += f"{duration(d.info['seconds']):>10}" + _met(d)
    if d.info.get("mirrored"):
        line += f"  (a model of the {p.part.name}, answering in the mirror)"
    if slow:
        line += (
            f"  (first call {duration(first)}: what this body and contact need, e.g. the "
            "linear FEM's columns, was computed and cached)"
        )
    print(line)
    env = d.info.get("envelope")
    if env and not env["inside"]:
        print(
            f"  NOTE: {name} answers outside the data it was trained and checked on: "
            f"{'; '.join(env['outside'])}. Check it with --compare"
        )
    for why in impossible(d.info):
        print(f"  WARNING: {name}: {why}: do not use this answer")


def truth(scene, args, failures: dict | None = None, force=None):
    """The FEM's answer to ``scene`` at the options' resolution, levels and fidelity, printed;
    ``None`` (and the reason printed, and kept in ``failures`` under the FEM's name) when the
    solve fails: the models' answers stand. ``force`` (N): the posed objects pressed until
    they meet it, by the FEM's own force control.
    """
    name = f"FEM ({args.res})" if args.tissue == "paper" else f"FEM ({args.res}, {args.tissue})"
    options = {
        "res": args.res,
        "levels": args.levels,
        "fidelity": args.fidelity,
        "tissue": args.tissue,
        "phenotype": phenotype_of(args),
        "friction": args.friction,
    }
    fem = predictor.create("fem", **options)
    k = kept.key(scene, kept.setup_of({**options, "force_N": force}), kept.code_of(fem))
    t0 = time.perf_counter()
    d = None if args.fresh else kept.read(k)
    note = ""
    if d is None:
        try:
            d = fem.predict(scene) if force is None else to_force(fem, scene, force)
        except PredictionFailed as e:
            print(f"{name:<{WIDTH}} failed: {e}; no errors to show")
            if failures is not None:
                failures[name] = str(e)
            return None
        took = d.info["seconds"]
        kept.write(k, d)
    else:
        took = time.perf_counter() - t0
        note = (
            f"; kept from an identical solve of {duration(d.info['seconds'])} "
            f"({d.info['kept']}; --fresh solves it again)"
        )
    print(
        f"{name:<{WIDTH}} deepest {1e3 * d.magnitude.max():6.3f} mm  "
        f"{duration(took):>10}" + _met(d) + note
    )
    return d


def _met(d) -> str:
    """What a posed scene's answer met: its reaction and peak contact pressure, and how force
    control found it ('' for a scene given by its force).
    """
    if d.reaction is None:
        return ""
    peak = d.pressure.max() / 1e3
    line = f"  {d.scene.pose.reaction_name} {d.reaction:.3g} N, peak pressure {peak:.3g} kPa"
    fc = d.info.get("force_control")
    if fc:
        n = fc["answers"]
        how = (
            "by its own force control"
            if n is None
            else f"found in {n} answer{'s' if n > 1 else ''}"
        )
        moved = "closed" if d.scene.pose.closing else "pressed"
        line += (
            f" ({moved} {fc['moved_mm']:.2f} mm on from the pose, {how}, "
            f"{duration(fc['seconds'])} in all)"
        )
    return line


def record(out: dict, fem, failures: dict) -> dict:
    """What a run found, for a file beside its pictures: every answer's deepest displacement
    (mm), time (s), whether it lies inside its data and is possible (with the reasons), its
    errors against the FEM's answer, and every solve that failed with why.
    """
    answers = {}
    for name, d in out.items():
        env = d.info.get("envelope") or {}
        a = {
            "deepest_mm": round(1e3 * float(d.magnitude.max()), 6),
            "seconds": d.info.get("seconds"),
            "inside_envelope": env.get("inside", True),
            "outside_because": env.get("outside", []),
            "physical": bool(d.info.get("physical", True)),
            "impossible_because": impossible(d.info),
        }
        if d.reaction is not None:
            a["reaction_N"] = round(float(d.reaction), 6)
            a["peak_pressure_kPa"] = round(float(d.pressure.max()) * 1e-3, 6)
        if fem is not None:
            m = sample_metrics(fem.displacement, d.displacement)
            a["against_fem"] = {k: round(float(m[k]), 6) for k in ("mee", "rel_mee", "peak_err")}
        answers[name] = a
    fem_record = None
    if fem is not None:
        fem_record = {
            "deepest_mm": round(1e3 * float(fem.magnitude.max()), 6),
            "seconds": fem.info.get("seconds"),
            "kept_from": fem.info.get("kept"),
        }
        if fem.reaction is not None:
            fem_record["reaction_N"] = round(float(fem.reaction), 6)
            fem_record["peak_pressure_kPa"] = round(float(fem.pressure.max()) * 1e-3, 6)
    return {"answers": answers, "fem": fem_record, "failed": dict(failures)}


def errors(out: dict, fem) -> None:
    """Print each answer's error against the FEM's ``fem``: its mean error in mm and as a share
    of the deepest displacement, its peak's error and its largest error.
    """
    for name, d in out.items():
        m = sample_metrics(fem.displacement, d.displacement)
        reaction = ""
        if d.reaction is not None and fem.reaction:
            reaction = f", reaction {100 * (d.reaction / fem.reaction - 1):+.1f} %"
        print(
            f"  {name}: MEE {m['mee']:.4f} mm = {m['rel_mee']:.2f} % of the deepest, peak "
            f"{m['peak_err']:+.1f} %, largest error {m['max_err']:.3f} mm{reaction}"
        )
