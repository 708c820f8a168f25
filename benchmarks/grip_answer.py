"""How long the grip models take to answer a grip, beside the gel's default GNN on a disk.

    python benchmarks/grip_answer.py [--repeat 3] [--split test]

The shipped grip models given a pose (``zoo:gnn_forearm_grips``, on the linear FEM's closure
of the hand, and ``zoo:linear_forearm_grips``, that closure itself) answer the grips of the
shipped grip set's ``--split`` (``data/forearm_grips``: anny's right hand closing on the layered
forearm of her left arm, the main job's arm of 2109 vertices), each a new scene: the predictor
forgets the closures it kept before each answer (``forget_scenes()``), as the main job's force
control and a moving hand meet a new pose at every answer. Beside them, the gel's default GNN
(``zoo:gnn_arm_bodies``) answers 0.3 N disks of 2 cm radius on 7.5 mm of tissue on the same
arm, the time per scene that issue's target is read against ("within 2x of the gel model's
time per scene at the same fidelity"). Each learned model first loads its compiled loops
(``load_kernels()``), as an application answering many scenes does; the grip GNN is also
answered with NumPy alone (``engine="numpy"``, what the main job uses: no torch import).

Besides the whole ``predict()``, the closure alone (:meth:`fem.holding.HeldSkin.closed` on each
grip's pose, forgotten before each call) and the held prior (the skin held where the hand
holds it and the linear FEM elsewhere). Medians over the grips and ``--repeat`` rounds, one
thread; run it alone: the times are wall-clock.
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
    times = []
    for r in range(repeat + 1):
        for c in calls:
            if forget is not None:
                forget()
            t0 = time.perf_counter()
            fn(c)
            if r:
                times.append(time.perf_counter() - t0)
    return 1e3 * float(np.median(times))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--split", default="test", choices=("train", "val", "test"))
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
    from stmpl.scene import Scene
    from stmpl.table import header, row

    torch.set_num_threads(1)
    root = pathlib.Path(__file__).parents[1]
    grips, _ = scenes_of(
        Dataset(root / "data" / "forearm_grips"), args.split, given="pose", way=True
    )
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
    print(header(["model", "fidelity", "engine", "ms a scene", "x the gel GNN"], "lllrr"))
    base = {}
    for fidelity in ("full", "auto"):
        p = gel.with_fidelity(fidelity)
        p.load_kernels()
        base[fidelity] = median_ms(p.predict, disks, args.repeat)
        print(row(["gnn_arm_bodies (a disk)", fidelity, "torch", f"{base[fidelity]:.1f}", "1"]))
    for name, engines in (
        ("gnn_forearm_grips", ("default", "numpy")),
        ("linear_forearm_grips", ("",)),
    ):
        for fidelity in ("full", "auto"):
            for engine in engines:
                p = zoo.read(name, fidelity=fidelity, **({"engine": engine} if engine else {}))
                if hasattr(p, "load_kernels"):
                    p.load_kernels()
                ms = median_ms(p.predict, grips, args.repeat, p.forget_scenes)
                ratio = ms / base[fidelity]
                shown = {"default": "torch", "": "numpy"}.get(engine, engine)
                print(row([name, fidelity, shown, f"{ms:.1f}", f"{ratio:.1f}"]))
    p = zoo.read("gnn_forearm_grips")
    skin = p.held_skin
    record = p.meta["holding"]
    friction, rounding = float(record["friction"]), float(record["rounding_m"])
    poses = []
    for s in grips:
        g = np.asarray(p.given([s]), dtype=np.float32)[0]
        poses.append((g[:, 0], g[:, 1:4], np.asarray(s.thickness, np.float32)))
    closure = median_ms(
        lambda c: skin.closed(*c[:2], c[2], friction, rounding),
        poses,
        args.repeat,
        skin.forget_closures,
    )
    print(
        row(["the grip GNN's closure alone (HeldSkin.closed)", "", "numpy", f"{closure:.1f}", ""])
    )
    for c in poses:
        skin.closed(*c[:2], c[2], friction, rounding)
    held = median_ms(
        lambda c: skin.answer(skin.closure(*c[:2], c[2], friction, rounding), c[0], c[2]),
        poses,
        args.repeat,
    )
    print(
        row(["the held prior on a kept closure (HeldSkin.answer)", "", "numpy", f"{held:.1f}", ""])
    )
    factor = median_ms(lambda c: skin.hold(c[0], c[2]), poses, args.repeat, skin._holds.clear)
    print(
        row(
            [
                "its factor, at a held set never met (HeldSkin.hold)",
                "",
                "numpy",
                f"{factor:.1f}",
                "",
            ]
        )
    )


if __name__ == "__main__":
    main()
