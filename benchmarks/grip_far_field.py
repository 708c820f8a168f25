"""How much of a grip's answer the linear FEM carries from the skin the hand holds: on the
layered forearm, friction drags the skin under the fingers along with them, and the skin layer
(stiff, over soft fat) carries that drag along the whole limb, beyond any message-passing
network's reach. Here the FEM's own displacement of the skin within a radius of the contact
is held, and the rest of the skin answered by the linear FEM of the same tissue (its tangent at
rest); the answer is compared with the FEM's on every vertex of the skin, near and far.

    python benchmarks/grip_far_field.py [--data data/forearm_grips] [--shards 2 12]
                                        [--hold 0.005 0.01 0.02] [--reach]

The linear FEM (:class:`fem.holding.Holding`) is meshed on the plain arm the data's arm was
subdivided from (the layered preset's element layers in quadratic elements, about 60k
unknowns; every vertex of the data's arm is one of its nodes), factorised once for each
thickness, and answers on the data's 2109 vertices. A few seconds a sample on one thread.
With ``--reach`` the vertices within reach of the hand (its gap below 2 cm: what a model given
the pose knows) are held as well, as the learned models' held prior holds them
(:class:`fem.holding.HeldSkin`: the float32 compliance, its columns solved once per thickness
and cached): that prior's answer were the network's near answer exact.
"""

from __future__ import annotations

import argparse
import json
import time

import numpy as np

FAR = 0.05
"""m: a vertex farther than this from every contact vertex is "far"."""
RES = {"subdivisions": 0, "layers": 1, "order": 2}
"""The linear FEM's mesh of the plain arm: the preset's element layers, quadratic elements."""


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", default="data/forearm_grips")
    ap.add_argument("--shards", type=int, nargs="+", default=[2, 12])
    ap.add_argument("--hold", type=float, nargs="*", default=[0.005, 0.01, 0.02], help="m")
    ap.add_argument(
        "--reach",
        action="store_true",
        help="also hold the vertices within reach of the hand (gap < 2 cm), as prior: held does",
    )
    args = ap.parse_args()

    import h5py
    from scipy.spatial import cKDTree

    from fem.holding import HeldSkin, Holding
    from stmpl.contact.gap import of_sample
    from stmpl.machine import describe
    from stmpl.part import BodyPart

    with np.load(f"{args.data}/part.npz") as z:
        arrays = dict(z)
    part = BodyPart.from_arrays(str(arrays["name"]), arrays, json.loads(str(arrays["source"])))
    print(describe())
    solvers = {}
    skin = HeldSkin(part, "forearm")
    print(
        "| shard | grip | force N | held within mm | held | rel. MEE % (skin at rest) "
        "| far: error / rest's |"
    )
    print("|---|---|--:|--:|--:|--:|--:|")
    for s in args.shards:
        with h5py.File(f"{args.data}/shard-{s:05d}.h5") as h:
            U, P, T = h["displacement"][:], h["pressure"][:], h["thickness"][:]
            G = h["gap"][:]
            params = [json.loads(p) for p in h["params"][:]]
            total = h["total"][:]
        key = round(float(T[0][0]), 6)
        if key not in solvers:
            t0 = time.perf_counter()
            solvers[key] = Holding(part, T[0].astype(float), RES, "forearm")
            print(
                f"(thickness {1e3 * key:g} mm: {solvers[key].unknowns} unknowns, factorised in "
                f"{time.perf_counter() - t0:.1f} s)"
            )
        holding = solvers[key]
        for i in range(len(U)):
            truth = U[i].astype(float)
            peak = np.linalg.norm(truth, axis=1).max()
            near = cKDTree(part.vertices[P[i] > 0]).query(part.vertices)[0]
            far = near > FAR
            rest = np.linalg.norm(truth, axis=1)
            rows = [(f"{1e3 * r:g}", np.flatnonzero(near < r), None) for r in args.hold]
            if args.reach:  # what a model knows: the vertices within reach of the hand
                gap = of_sample(part.vertices, "press_grip", params[i], G[i])
                rows.append(("reach", skin.held(gap, T[i]), gap))
            for label, held, gap in rows:
                if gap is None:
                    u = holding.answer(held, truth)
                else:  # the held prior's own answer (float32 compliance, cached)
                    u = skin.answer(truth.astype(np.float32), gap, T[i]).astype(float)
                e = np.linalg.norm(u - truth, axis=1)
                print(
                    f"| {s} | {params[i]['grip']} at {params[i]['along']:g} | {total[i]:.0f} | "
                    f"{label} | {len(held)} | {100 * e.mean() / peak:.2f} "
                    f"({100 * rest.mean() / peak:.2f}) | {e[far].mean() / rest[far].mean():.2f} |"
                )


if __name__ == "__main__":
    main()
