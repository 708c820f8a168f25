"""FEM speed and mesh convergence on the anny left arm.

For each resolution (fem.simulate.RESOLUTIONS), in a fresh process so that peak memory is its own:
DOFs, tetrahedra, Newton iterations, median time per simulation from rest, median time per force
level inside a 10-level continuation, peak resident memory. Then the convergence study: the
loaded vertices' displacement against the finest mesh; the reference resolution is the coarsest
within 2 %.

Run: python benchmarks/fem_speed.py [--thickness 7.5] [--radius 2] [--force 0.2] [--top 1.0]
Target: median <= 1.0 s per simulation at the reference resolution on 2 cores
(the paper: 84 +- 53 s per simulation with PolyFEM on one CPU thread).
"""

from __future__ import annotations

import argparse
import concurrent.futures as cf
import multiprocessing as mp
import os
import platform
import resource

import numpy as np

from stmpl.table import header, row

PLACEMENTS = (300, 200, 400)
"""Disk centres (vertex indices of the anny left arm) on the upper arm, elbow and forearm."""


def _run(
    name: str,
    thickness: float,
    radius: float,
    force: float,
    top: float,
    levels: int,
    placements: tuple,
) -> dict:
    import time

    from fem.simulate import RESOLUTIONS, mesh_for_load
    from fem.solver import Solver
    from stmpl import AnnyBody, loads

    part = AnnyBody().part("left_arm")
    res = RESOLUTIONS[name]
    warm = loads.disk(part, at=PLACEMENTS[0], radius=radius, total=0.01)  # load compiled code
    Solver(mesh_for_load(part, np.full(part.n_vertices, thickness), warm.force, "coarse")).solve(
        warm.force
    )
    out = {
        "name": name,
        "res": res.to_dict(),
        "rest": [],
        "level": [],
        "iters_rest": [],
        "iters_level": [],
        "u": [],
        "dofs": [],
        "tets": [],
        "failed": [],
    }
    for n, at in enumerate(PLACEMENTS):
        ld = loads.disk(part, at=at, radius=radius, total=force)
        t0 = time.perf_counter()
        mesh = mesh_for_load(part, np.full(part.n_vertices, thickness), ld.force, res)
        solver = Solver(mesh, order=res.order)
        setup = time.perf_counter() - t0
        sol = solver.solve(ld.force)
        if not sol.ok:
            out["failed"].append(f"{at}: {sol.reason}")
            continue
        out["rest"].append(setup + sol.time)
        out["iters_rest"].append(sol.iterations)
        out["u"].append(sol.part_displacement(mesh)[ld.vertices].tolist())
        out["dofs"].append(len(solver.free))
        out["tets"].append(len(mesh.tets))
        if at not in placements:
            continue
        totals = top * np.arange(1, levels + 1) / levels
        for s in solver.continuation(ld.force, totals):
            if s.ok:
                out["level"].append(s.time)
                out["iters_level"].append(s.iterations)
            else:
                out["failed"].append(f"{at} @ {s.total_force:.2f} N: {s.reason}")
    out["peak_mb"] = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    return out


def _assembly_vs_skfem() -> list[str]:
    """Time one residual + tangent assembly: the Numba kernel against scikit-fem's forms."""
    import time

    from fem.material import lame
    from fem.simulate import RESOLUTIONS, mesh_for_load
    from fem.skfem_forms import assemble
    from fem.solver import Solver
    from stmpl import AnnyBody, loads

    part = AnnyBody().part("left_arm")
    ld = loads.disk(part, at=PLACEMENTS[0], radius=0.02, total=0.1)
    mu, lam = lame(1000.0, 0.4)
    out = []
    for name in ("coarse", "fine"):
        res = RESOLUTIONS[name]
        mesh = mesh_for_load(part, np.full(part.n_vertices, 0.0075), ld.force, res)
        S = Solver(mesh, order=res.order)
        u = np.zeros((S.n_all, 3))
        S.assemble(u, u)
        t = []
        for _ in range(5):
            t0 = time.perf_counter()
            S.assemble(u, u)
            t.append(time.perf_counter() - t0)
        t0 = time.perf_counter()
        assemble(
            mesh.nodes,
            mesh.tets,
            np.zeros((mesh.n_nodes, 3)) if res.order == 1 else np.zeros(3 * S.n_all),
            mu,
            lam,
            res.order,
        )
        tsk = time.perf_counter() - t0
        ours = float(np.median(t))
        out.append(
            row(
                [name, f"P{res.order}", len(mesh.tets), f"{1e3 * ours:.0f}"]
                + [f"{1e3 * tsk:.0f}", f"{tsk / ours:.0f}x"]
            )
        )
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--thickness", type=float, default=7.5, help="mm")
    ap.add_argument("--radius", type=float, default=2.0, help="disk radius, cm")
    ap.add_argument(
        "--force", type=float, default=0.2, help="total force of the convergence study, N"
    )
    ap.add_argument("--top", type=float, default=1.0, help="last continuation level, N")
    ap.add_argument("--levels", type=int, default=10)
    args = ap.parse_args()
    from fem.linear_solvers import available_linear_solvers
    from fem.simulate import REFERENCE, RESOLUTIONS

    print(
        f"machine: {platform.processor() or platform.machine()}, {os.cpu_count()} cores; "
        f"linear solvers here: {', '.join(available_linear_solvers())}"
    )
    print(
        f"anny left arm, thickness {args.thickness} mm, disk radius {args.radius} cm at "
        f"vertices {PLACEMENTS}; convergence and time from rest at F_total {args.force} N; "
        f"continuation: {args.levels} levels up to {args.top} N; Neo-Hookean E = 1 kPa, "
        f"nu = 0.4"
    )
    ctx = mp.get_context("spawn")
    rows = []
    for name in RESOLUTIONS:
        with cf.ProcessPoolExecutor(1, mp_context=ctx) as ex:
            # the finest mesh runs its continuation on one placement only (minutes otherwise)
            pls = PLACEMENTS[:1] if name == list(RESOLUTIONS)[-1] else PLACEMENTS
            rows.append(
                ex.submit(
                    _run,
                    name,
                    args.thickness / 1e3,
                    args.radius / 100,
                    args.force,
                    args.top,
                    args.levels,
                    pls,
                ).result()
            )
    finest = rows[-1]
    print()
    columns = ["resolution", "order", "subdiv", "layers", "DOFs", "tets"]
    columns += ["Newton its from rest", "s/sim from rest", "its/level"]
    columns += ["s/level (continuation)", "peak MB", "loaded-vertex error vs finest"]
    print(header(columns, "l" + "r" * 11))
    errs = {}
    for r in rows:
        e = []
        for u, uf in zip(r["u"], finest["u"]):
            u, uf = np.asarray(u), np.asarray(uf)
            e.append(np.linalg.norm(u - uf) / np.linalg.norm(uf))
        errs[r["name"]] = max(e) if e else float("nan")
        print(
            row(
                [r["name"], f"P{r['res']['order']}", r["res"]["subdivisions"], r["res"]["layers"]]
                + [int(np.median(r["dofs"])), int(np.median(r["tets"]))]
                + [f"{np.median(r['iters_rest']):.0f}", f"{np.median(r['rest']):.2f}"]
                + [f"{np.median(r['iters_level']):.0f}", f"{np.median(r['level']):.2f}"]
                + [f"{r['peak_mb']:.0f}", f"{100 * errs[r['name']]:.2f} %"]
            )
        )
        for f in r["failed"]:
            print(f"  failed ({r['name']}): {f}")
    chosen = next(n for n in RESOLUTIONS if errs[n] <= 0.02)
    ref = next(r for r in rows if r["name"] == REFERENCE)
    print()
    print(
        f"coarsest resolution within 2 % of the finest: {chosen} (fem.simulate.REFERENCE = "
        f"{REFERENCE!r})"
    )
    print()
    print("one residual + tangent assembly (Neo-Hookean), ours against scikit-fem's forms:")
    print(header(["mesh", "order", "tets", "ours ms", "scikit-fem ms", "ratio"], "lrrrrr"))
    with cf.ProcessPoolExecutor(1, mp_context=ctx) as ex:
        for line in ex.submit(_assembly_vs_skfem).result():
            print(line)
    t_rest, t_level = np.median(ref["rest"]), np.median(ref["level"])
    print(
        f"reference: {t_rest:.2f} s per simulation from rest, {t_level:.2f} s per level in a "
        f"continuation; target <= 1.0 s; paper 84 s -> {84 / t_rest:.0f}x / "
        f"{84 / t_level:.0f}x faster"
    )


if __name__ == "__main__":
    main()
