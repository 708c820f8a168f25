"""How long the grip models take to answer a grip, beside the gel's default GNN on a disk.

    python benchmarks/grip_answer.py [--repeat 3] [--split test] [--gnn SPEC ...]

The shipped grip models given a pose (``zoo:gnn_forearm_grips``, on the linear FEM's closure
of the hand, the skin held at its answer near the hand; ``zoo:gnn_forearm_grips_fast``, forces
on the held skin, no factor; and ``zoo:linear_forearm_grips``, that closure itself) answer
the grips of the shipped grip set's ``--split`` (``data/forearm_grips``: anny's right hand
closing on the layered forearm of her left arm, the main job's arm of 2109 vertices), each a
new scene: the predictor forgets the closures and the held sets' factors it kept before each
answer (``forget_scenes()``), as the main job's force control and a moving hand meet a new
pose, and nearly always a new held set, at every answer. Beside them, the gel's default GNN
(``zoo:gnn_arm_bodies``) answers 0.3 N disks of 2 cm radius on 7.5 mm of tissue on the same
arm, and the same grips given by their force (the FEM's contact force on each vertex: the
paper's load model, the scene the gel's models answer of a grasp): the grip models are held to
within twice its time per scene at the same fidelity. The grip models are timed two ways: as
the main job
answers (NumPy alone, Numba not yet loaded, so the closure's steps run in NumPy), and as an
application answering many scenes does (the compiled loops loaded: ``load_kernels()``, the
GNN in torch, the closure's steps compiled); the gel's GNN with its loops loaded. The compiled
rows, the gel's GNN among them, take turns round by round (:func:`interleaved`), so that the
ratios hold on a machine whose speed drifts.

Besides the whole ``predict()``, the closure alone (:meth:`fem.holding.HeldSkin.closed` on each
grip's pose, forgotten before each call) both ways, and the held prior (the skin held where the
hand holds it and the linear FEM elsewhere), with its factor kept and at a held set never met.
Medians over the grips and ``--repeat`` rounds, one thread; run it alone: the times are
wall-clock. ``--gnn`` times other grip GNNs (``zoo:<name>`` or checkpoint
paths, as ``stmpl evaluate`` names them) in place of the two shipped ones.
"""

from __future__ import annotations

import argparse
import os
import pathlib
import time
import warnings

import numpy as np


def median_ms(fn, calls, repeat: int, forget=None) -> float:
    """The median of ``fn(c)`` over ``calls`` and ``repeat`` rounds (after one warm-up
    round), ms; ``forget()`` before each call.
    """
    return interleaved([(None, fn, calls, forget)], repeat)[None]


def interleaved(timers, repeat: int) -> dict:
    """``{key: median ms}`` of each timer ``(key, fn, calls, forget)`` as :func:`median_ms`
    times it, the timers taking turns round by round (one warm-up round first): on a shared
    machine whose speed drifts over minutes, each timer's rounds then meet the same drift, and
    the ratios between them hold where the absolute times move.
    """
    times = {key: [] for key, *_ in timers}
    for r in range(repeat + 1):
        for key, fn, calls, forget in timers:
            for c in calls:
                if forget is not None:
                    forget()
                t0 = time.perf_counter()
                fn(c)
                if r:
                    times[key].append(time.perf_counter() - t0)
    return {key: 1e3 * float(np.median(t)) for key, t in times.items()}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--split", default="test", choices=("train", "val", "test"))
    ap.add_argument(
        "--gnn",
        nargs="+",
        default=["zoo:gnn_forearm_grips", "zoo:gnn_forearm_grips_fast"],
        help="grip GNNs to time: zoo:<name> or .safetensors checkpoints",
    )
    args = ap.parse_args()
    os.environ.setdefault("OMP_NUM_THREADS", "1")
    os.environ.setdefault("MKL_NUM_THREADS", "1")
    warnings.simplefilter("ignore")  # the envelopes' notes on the grips

    import torch

    from stmpl import loads, tissue
    from stmpl.data.dataset import Dataset
    from stmpl.machine import describe
    from stmpl.pipeline import zoo
    from stmpl.pipeline.evaluate import scenes_of
    from stmpl.pipeline.spec import label, predictor_from_spec
    from stmpl.scene import Scene
    from stmpl.table import header, row

    torch.set_num_threads(1)
    root = pathlib.Path(__file__).parents[1]
    grip_set = Dataset(root / "data" / "forearm_grips")
    grips, _ = scenes_of(grip_set, args.split, given="pose", way=True)
    by_force, _ = scenes_of(grip_set, args.split)  # the same grips, their contact force given
    gel = zoo.read("gnn_arm_bodies")
    arm = gel.part
    rng = np.random.default_rng(0)
    thick = tissue.constant(arm, 0.0075)
    disks = []
    while len(disks) < len(grips):
        uv = tuple(rng.uniform(0.38, 0.62, 2))
        try:
            disks.append(
                Scene.from_load(arm, thick, loads.disk(arm, uv=uv, radius=0.02, total=0.3))
            )
        except ValueError:  # off the chart: another place
            continue
    print(
        f"{len(grips)} grips of data/forearm_grips ({args.split}), {len(disks)} disks; one thread"
    )
    print(describe())
    import fem.closure
    from stmpl import jit

    models = [*args.gnn, "zoo:linear_forearm_grips"]
    grip = zoo.read("gnn_forearm_grips")
    skin = grip.held_skin
    closing = grip.closure_options()
    poses = []
    for s in grips:
        g = np.asarray(grip.given([s]), dtype=np.float32)[0]
        poses.append((g[:, 0], g[:, 1:4], np.asarray(s.thickness, np.float32)))

    def closed(c):
        return skin.closed(*c[:2], c[2], *closing)

    columns = [
        "model",
        "fidelity",
        "engine",
        "ms a scene",
        "x the gel GNN: disk",
        ": grip by force",
    ]
    print(header(columns, "lllrrr"))
    rows = []  # (model, fidelity, engine, ms)
    # as the main job answers: NumPy alone, Numba not loaded (the closure in NumPy too)
    assert not jit.loaded(), "Numba was loaded before the NumPy rows"
    for fidelity in ("full", "auto"):
        for name in models:
            engine = "numpy" if name in args.gnn else "default"
            p = predictor_from_spec(name, fidelity=fidelity, engine=engine)
            ms = median_ms(p.predict, grips, args.repeat, p.forget_scenes)
            rows.append((name, fidelity, "numpy", ms))
    closure_numpy = median_ms(closed, poses, args.repeat, skin.forget_closures)
    # as an application answering many scenes does: the compiled loops loaded; every model,
    # the gel's GNN among them, timed in turns (interleaved)
    timers = []
    for fidelity in ("full", "auto"):
        for name in models:
            p = predictor_from_spec(name, fidelity=fidelity)
            p.load_kernels()  # the GNN's subgraph and fused steps (none for the linear FEM)
            engine = ("torch" if name in args.gnn else "numpy") + ", loops compiled"
            fem.closure._kernel()  # the closure's loop (Numba's disk cache)
            timers.append(((name, fidelity, engine), p.predict, grips, p.forget_scenes))
        p = gel.with_fidelity(fidelity)
        p.load_kernels()
        timers.append((("disk", fidelity), p.predict, disks, None))
        timers.append(
            (("grasp", fidelity), lambda s, p=p: p.predict(s, strict=False), by_force, None)
        )
    timers.append((("closure",), closed, poses, skin.forget_closures))
    ms = interleaved(timers, args.repeat)
    rows += [key + (ms[key],) for key, *_ in timers if len(key) == 3]
    closure_compiled = ms[("closure",)]
    base = {f: ms[("disk", f)] for f in ("full", "auto")}
    grasp = {f: ms[("grasp", f)] for f in ("full", "auto")}
    for fidelity in ("full", "auto"):
        for what, t in (("a disk", base[fidelity]), ("the grip by force", grasp[fidelity])):
            cells = [f"gnn_arm_bodies ({what})", fidelity, "torch, loops compiled", f"{t:.1f}"]
            print(row([*cells, f"{t / base[fidelity]:.1f}", f"{t / grasp[fidelity]:.1f}"]))
    for name, fidelity, engine, ms in rows:
        cells = [label(name), fidelity, engine, f"{ms:.1f}", f"{ms / base[fidelity]:.1f}"]
        print(row([*cells, f"{ms / grasp[fidelity]:.1f}"]))
    print()
    print(header(["part of a grip's answer", "ms"], "lr"))
    print(row(["the closure (HeldSkin.closed), NumPy", f"{closure_numpy:.2f}"]))
    print(row(["the closure, its steps compiled", f"{closure_compiled:.2f}"]))
    for c in poses:
        closed(c)
    held = median_ms(
        lambda c: skin.answer(skin.closure(*c[:2], c[2], *closing), c[0], c[2]),
        poses,
        args.repeat,
    )
    print(row(["the held prior on a kept closure and factor (HeldSkin.answer)", f"{held:.2f}"]))
    factor = median_ms(lambda c: skin.hold(c[0], c[2]), poses, args.repeat, skin._holds.clear)
    print(row(["its factor, at a held set never met (HeldSkin.hold)", f"{factor:.2f}"]))


if __name__ == "__main__":
    main()
