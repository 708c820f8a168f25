"""The local FEM against the whole-part solve (fidelity auto against full).

Two ways, both printing the largest and median error per sample relative to its deepest
displacement, and the solve time ratio:

    python benchmarks/fidelity.py --datasets FULL AUTO
        the samples two datasets of one plan share (same task and force), e.g. a few shards of a
        reference set made with fidelity full beside the same shards made with auto; times are
        the solves' own, as recorded in the shards.

    python benchmarks/fidelity.py --live DATASET [--count 6]
        solves the first test placements of DATASET's plan both ways now, one after the other
        (run it alone on the machine: the ratio is only as good as the quiet around it).
"""

from __future__ import annotations

import argparse
import platform
import time

import numpy as np


def _samples(folder) -> dict:
    """``{(task, force): (displacement (N, 3), solve seconds)}`` of a dataset folder's shards
    (read as written, whatever the card says, so an unfinished dataset can be compared)."""
    import glob

    import h5py

    out = {}
    for f in sorted(glob.glob(f"{folder}/shard-*.h5")):
        with h5py.File(f) as h:
            for i, (t, tot) in enumerate(zip(h["task"][:], h["total"][:])):
                out[(int(t), round(float(tot), 4))] = (h["displacement"][i], h["solve_time"][i])
    return out


def compare_datasets(full: str, auto: str) -> None:
    a, b = _samples(full), _samples(auto)
    common = sorted(set(a) & set(b))
    if not common:
        raise SystemExit("the two folders share no (task, force) sample")
    err, ta, tb = [], 0.0, 0.0
    for k in common:
        (ua, sa), (ub, sb) = a[k], b[k]
        peak = np.linalg.norm(ua, axis=1).max()
        err.append(np.linalg.norm(ub - ua, axis=1).max() / peak)
        ta, tb = ta + sa, tb + sb
    err = 100 * np.asarray(err)
    print(f"{len(common)} samples in common; largest error {err.max():.3f} % of the deepest "
          f"(median {np.median(err):.4f} %); solve time full {ta:.0f} s, auto {tb:.0f} s: "
          f"{ta / tb:.2f} x")


def live(folder: str, count: int) -> None:
    from fem.config import read_config
    from fem.local import simulate_local
    from fem.material import material
    from fem.placements import make_load, plan
    from fem.simulate import simulate
    from fem.solver import SolverOptions
    from stmpl.dataset import Dataset

    ds = Dataset(folder)
    cfg = read_config(ds.card["config"])
    p = plan(cfg, ds.part)
    mat, opts = material(**cfg["material"]), SolverOptions(**cfg["solver"])
    forces = np.asarray(cfg["forces"], float)
    print(f"{'placement':<40} {'full s':>7} {'auto s':>7} {'ratio':>6} {'max err %':>9} "
          f"{'patch':>11}")
    ratios, errs = [], []
    for i, pl in enumerate(p.placements[:count]):
        load = make_load(ds.part, pl)
        t = np.full(ds.part.n_vertices, cfg["thickness_mm"][len(cfg["thickness_mm"]) // 2] * 1e-3)
        levels = forces[forces / load.area <= cfg["max_pressure"]]
        t0 = time.perf_counter()
        mesh, sols = simulate(ds.part, t, load.force, levels, cfg["resolution"], mat, opts)
        tf = time.perf_counter() - t0
        t0 = time.perf_counter()
        m2, s2, res = simulate_local(ds.part, t, load.force, levels, cfg["resolution"], mat,
                                     opts)
        tl = time.perf_counter() - t0
        ok = [k for k, (x, y) in enumerate(zip(sols, s2)) if x.ok and y.ok]
        e = max((np.linalg.norm(res.patch.lift(s2[k].part_displacement(m2), ds.part.n_vertices)
                                - sols[k].part_displacement(mesh), axis=1).max()
                 / np.linalg.norm(sols[k].part_displacement(mesh), axis=1).max())
                for k in ok) if ok else np.nan
        ratios.append(tf / tl)
        errs.append(100 * e)
        name = f"{pl['kind']} {pl['params']}"[:40]
        print(f"{name:<40} {tf:7.1f} {tl:7.1f} {tf / tl:6.2f} {100 * e:9.3f} "
              f"{len(res.patch.vertices):>5}/{ds.part.n_vertices}")
    print(f"median ratio {np.median(ratios):.2f} x, largest error {np.nanmax(errs):.3f} % of the "
          "deepest")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    g = ap.add_mutually_exclusive_group(required=True)
    g.add_argument("--datasets", nargs=2, metavar=("FULL", "AUTO"))
    g.add_argument("--live", metavar="DATASET")
    ap.add_argument("--count", type=int, default=6)
    args = ap.parse_args()
    print(f"machine: {platform.processor() or platform.machine()}, "
          f"{__import__('os').cpu_count()} cores")
    if args.datasets:
        compare_datasets(*args.datasets)
    else:
        live(args.live, args.count)


if __name__ == "__main__":
    main()
