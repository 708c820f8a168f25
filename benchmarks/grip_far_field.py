"""How much of a grip's answer the linear FEM carries from the skin the hand holds: on the
layered forearm, friction drags the skin under the fingers along with them, and the skin layer
(stiff, over soft fat) carries that drag along the whole limb, beyond any message-passing
network's reach. Here the FEM's own displacement of the skin within a radius of the contact
is held, and the rest of the skin answered by the linear FEM of the same tissue (its tangent at
rest); the answer is compared with the FEM's on the plain arm's vertices, near and far.

    python benchmarks/grip_far_field.py [--data data/forearm_grips] [--shards 2 12]
                                        [--hold 0.005 0.01 0.02]

The linear FEM is the plain arm's (the data's first vertices; medium resolution: the layered
preset's element layers in quadratic elements, about 60k unknowns), factorised once for each
thickness. Held vertices get unit nodal forces in x, y and z; the forces that put them at the
FEM's displacement follow from those columns, and the whole skin's answer from the same
columns. A few seconds a sample on one thread.
"""

from __future__ import annotations

import argparse
import json
import time

import numpy as np

FAR = 0.05
"""m: a vertex farther than this from every contact vertex is "far"."""


def linear_solver(part, thickness: np.ndarray):
    """The linear FEM of the forearm preset on ``part`` (thickness ``(N,)`` m of skin and
    fat), factorised; and each free DOF's row.
    """
    from fem.simulate import tissue_mesh
    from fem.solver import Solver

    mesh, material = tissue_mesh(
        part, thickness, {"subdivisions": 0, "layers": 1, "order": 2}, "forearm"
    )
    solver = Solver(mesh, material, order=2)
    u0 = np.zeros((solver.n_all, 3))
    _, K = solver.assemble(u0, u0)
    solver.linear.factor(K)
    row = np.full(solver.n_all * 3, -1)
    row[solver.free] = np.arange(len(solver.free))
    return solver, row


def held_answer(solver, row, held: np.ndarray, target: np.ndarray) -> np.ndarray:
    """``(N, 3)`` the linear FEM's skin displacement (m) with the part vertices ``held`` at
    ``target[held]`` ``(N, 3)``.
    """
    nodes = solver.mesh.part_nodes
    n = len(nodes)
    rows = row[(nodes[held][:, None] * 3 + np.arange(3)).ravel()]
    B = np.zeros((len(solver.free), len(rows)), order="F")
    B[rows, np.arange(len(rows))] = 1.0
    X = np.zeros((solver.n_all * 3, len(rows)))
    X[solver.free] = solver.linear.solve(B)
    G = X.reshape(solver.n_all, 3, -1)[nodes].reshape(3 * n, -1)  # skin DOFs x held DOFs
    sel = (np.asarray(held)[:, None] * 3 + np.arange(3)).ravel()
    forces = np.linalg.solve(G[sel], target[held].ravel())
    return (G @ forces).reshape(n, 3)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", default="data/forearm_grips")
    ap.add_argument("--shards", type=int, nargs="+", default=[2, 12])
    ap.add_argument("--hold", type=float, nargs="+", default=[0.005, 0.01, 0.02], help="m")
    args = ap.parse_args()

    import h5py
    from scipy.spatial import cKDTree

    from stmpl.machine import describe
    from stmpl.part import BodyPart

    with np.load(f"{args.data}/part.npz") as z:
        arrays = dict(z)
    fine = BodyPart.from_arrays(str(arrays["name"]), arrays, json.loads(str(arrays["source"])))
    part = fine.coarser
    if part is None:
        raise SystemExit(
            f"{args.data}: its part is not a subdivided one; no plain part to solve on"
        )
    n = part.n_vertices
    print(describe())
    solvers = {}
    print(
        "| shard | grip | force N | held within mm | held | rel. MEE % (skin at rest) "
        "| far: error / rest's |"
    )
    print("|---|---|--:|--:|--:|--:|--:|")
    for s in args.shards:
        with h5py.File(f"{args.data}/shard-{s:05d}.h5") as h:
            U, P, T = h["displacement"][:], h["pressure"][:], h["thickness"][:]
            params = [json.loads(p) for p in h["params"][:]]
            total = h["total"][:]
        key = round(float(T[0][0]), 6)
        if key not in solvers:
            t0 = time.perf_counter()
            solvers[key] = linear_solver(part, T[0][:n].astype(float))
            print(f"(thickness {1e3 * key:g} mm: factorised in {time.perf_counter() - t0:.1f} s)")
        solver, row = solvers[key]
        for i in range(len(U)):
            truth = U[i][:n].astype(float)
            peak = np.linalg.norm(U[i], axis=1).max()
            near = cKDTree(fine.vertices[P[i] > 0]).query(part.vertices)[0]
            far = near > FAR
            rest = np.linalg.norm(truth, axis=1)
            for r in args.hold:
                held = np.flatnonzero(near < r)
                u = held_answer(solver, row, held, truth)
                e = np.linalg.norm(u - truth, axis=1)
                print(
                    f"| {s} | {params[i]['grip']} at {params[i]['along']:g} | {total[i]:.0f} | "
                    f"{1e3 * r:g} | {len(held)} | {100 * e.mean() / peak:.2f} "
                    f"({100 * rest.mean() / peak:.2f}) | {e[far].mean() / rest[far].mean():.2f} |"
                )


if __name__ == "__main__":
    main()
