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

    python benchmarks/fidelity.py --models SPEC [SPEC ...] --data DATASET [DATASET ...]
        the learned predictors (zoo:<name> or checkpoints) at fidelity full and auto on each
        dataset's test split: time per scene at batch 1 and 64, relative MEE and peak error
        against the FEM for both, and auto's largest difference from full relative to the
        deepest displacement (run it alone).
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from stmpl.table import header, row


def _samples(folder) -> dict:
    """``{(task, force): (displacement (N, 3), solve seconds)}`` of a dataset folder's shards
    (read as written, whatever the card says, so an unfinished dataset can be compared).
    """
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
    print(
        f"{len(common)} samples in common; largest error {err.max():.3f} % of the deepest "
        f"(median {np.median(err):.4f} %); solve time full {ta:.0f} s, auto {tb:.0f} s: "
        f"{ta / tb:.2f} x"
    )


VARIANT_KEYS = {
    "refine": "refine_radius (m) of the patch's mesh",
    "thicknesses": "first margin: contact radius + this many thicknesses",
    "tolerance": "largest motion of the ring inside the cut, of the deepest",
}


def variant(text: str) -> dict:
    """``--variant refine=0.02,thicknesses=3,tolerance=0.01`` -> a dict of floats."""
    out = {}
    for item in text.split(","):
        k, _, v = item.partition("=")
        if k not in VARIANT_KEYS or not v:
            raise argparse.ArgumentTypeError(
                f"--variant takes {sorted(VARIANT_KEYS)}=number, got {item!r}"
            )
        out[k] = float(v)
    return out


def live(folder: str, count: int, variants=({},), every: int = 1) -> None:
    """``count`` placements (every ``every``-th of the dataset's plan, from the first) solved on
    the whole part, then on the patch once per variant of the local FEM (default: as shipped);
    the summary gives each variant's median ratio and the ratio of the summed times (what
    making those samples costs).
    """
    from fem.config import read_config
    from fem.local import simulate_local
    from fem.material import material
    from fem.placements import make_load, plan
    from fem.simulate import resolution, simulate
    from fem.solver import SolverOptions
    from stmpl.data.dataset import Dataset
    from stmpl.reach import RING_TOLERANCE, first_margin

    ds = Dataset(folder)
    cfg = read_config(ds.card["config"])
    p = plan(cfg, ds.part)
    mat, opts = material(**cfg["material"]), SolverOptions(**cfg["solver"])
    forces = np.asarray(cfg["forces"], float)
    print(
        f"{'placement':<40} {'variant':<34} {'full s':>7} {'auto s':>7} {'ratio':>6} "
        f"{'max err %':>9} {'patch':>11} ring moved % per attempt"
    )
    ratios, errs = {}, {}
    full_s, auto_s = [], {}
    for i, pl in enumerate(p.placements[::every][:count]):
        load = make_load(ds.part, pl)
        t = np.full(ds.part.n_vertices, cfg["thickness_mm"][len(cfg["thickness_mm"]) // 2] * 1e-3)
        levels = forces[forces / load.area <= cfg["max_pressure"]]
        t0 = time.perf_counter()
        mesh, sols = simulate(ds.part, t, load.force, levels, cfg["resolution"], mat, opts)
        tf = time.perf_counter() - t0
        full_s.append(tf)
        for v in variants:
            res = resolution(cfg["resolution"]).to_dict()
            if "refine" in v:
                res["refine_radius"] = v["refine"]
            margin = (
                first_margin(ds.part, t, load.force, v["thicknesses"])
                if "thicknesses" in v
                else None
            )
            t0 = time.perf_counter()
            m2, s2, r = simulate_local(
                ds.part,
                t,
                load.force,
                levels,
                res,
                mat,
                opts,
                margin=margin,
                tolerance=v.get("tolerance", RING_TOLERANCE),
            )
            tl = time.perf_counter() - t0
            ok = [k for k, (x, y) in enumerate(zip(sols, s2)) if x.ok and y.ok]
            e = (
                max(
                    (
                        np.linalg.norm(
                            r.patch.lift(s2[k].part_displacement(m2), ds.part.n_vertices)
                            - sols[k].part_displacement(mesh),
                            axis=1,
                        ).max()
                        / np.linalg.norm(sols[k].part_displacement(mesh), axis=1).max()
                    )
                    for k in ok
                )
                if ok
                else np.nan
            )
            name = ",".join(f"{k}={x:g}" for k, x in v.items()) or "as shipped"
            ratios.setdefault(name, []).append(tf / tl)
            auto_s.setdefault(name, []).append(tl)
            errs.setdefault(name, []).append(100 * e)
            ring = " ".join(f"{100 * a['ring_moved']:.2f}" for a in r.attempts)
            label = f"{pl['kind']} {pl['params']}"[:40]
            print(
                f"{label:<40} {name:<34} {tf:7.1f} {tl:7.1f} {tf / tl:6.2f} {100 * e:9.3f} "
                f"{len(r.patch.vertices):>5}/{ds.part.n_vertices} {ring}",
                flush=True,
            )
    for name in ratios:
        print(
            f"{name}: median ratio {np.median(ratios[name]):.2f} x (range "
            f"{min(ratios[name]):.2f}-{max(ratios[name]):.2f}), summed times "
            f"{sum(full_s):.0f} s / {sum(auto_s[name]):.0f} s = "
            f"{sum(full_s) / sum(auto_s[name]):.2f} x, largest error "
            f"{np.nanmax(errs[name]):.3f} % of the deepest"
        )


def models(specs, datasets, limit: int = 64, repeat: int = 5, tolerances=()) -> None:
    """``tolerances``: also run auto with these region tolerances (the share of the prior's
    deepest displacement above which a vertex is in the region, :data:`stmpl.reach.
    REGION_TOLERANCE`, given to each predictor at construction), to show what a smaller region
    buys.
    """
    import warnings

    from _timing import median_time

    from stmpl.data.dataset import Dataset
    from stmpl.metrics import sample_metrics, summarise
    from stmpl.pipeline.evaluate import scenes_of
    from stmpl.pipeline.spec import label, predictor_from_spec
    from stmpl.reach import REGION_TOLERANCE

    warnings.simplefilter("ignore")  # envelope notes: not what is measured
    columns = ["model", "data", "fidelity", "ms/scene batch 1", "ms/scene batch 64"]
    columns += ["rel. MEE %", "peak err % (mean, max abs)", "largest diff. from full, % of deepest"]
    print(header(columns, "lllrrrrr"))
    for folder in datasets:
        ds = Dataset(folder)
        scenes, truth = scenes_of(ds, "test", limit=limit)
        for spec in specs:
            full = None
            shipped = REGION_TOLERANCE
            for fid, tol in [
                ("full", shipped),
                ("auto", shipped),
                *[("auto", x) for x in tolerances if x != shipped],
            ]:
                p = predictor_from_spec(spec, fidelity=fid, region_tolerance=tol)
                pred = [d.displacement for d in p.predict(scenes)]  # warm (columns cached)
                t1 = median_time(lambda: p.predict(scenes[0]), repeat)
                t64 = median_time(lambda: p.predict(scenes), max(1, repeat // 2)) / len(scenes)
                rows = [sample_metrics(t, u) for t, u in zip(truth, pred)]
                m = summarise(rows)
                pk = np.array([r["peak_err"] for r in rows])
                if full is None:
                    full, diff = pred, ""
                else:
                    d = max(
                        np.linalg.norm(a - b, axis=1).max() / np.linalg.norm(b, axis=1).max()
                        for a, b in zip(pred, full)
                    )
                    diff = f"{100 * d:.3f}"
                name = fid if tol == shipped else f"auto, region {100 * tol:g} %"
                cells = [label(spec), ds.card["name"], name, f"{1e3 * t1:.2f}"]
                cells += [f"{1e3 * t64:.3f}", f"{m['rel_mee'][0]:.3f}"]
                cells += [f"{pk.mean():+.2f}, {np.abs(pk).max():.1f}", diff]
                print(row(cells), flush=True)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    g = ap.add_mutually_exclusive_group(required=True)
    g.add_argument("--datasets", nargs=2, metavar=("FULL", "AUTO"))
    g.add_argument("--live", metavar="DATASET")
    g.add_argument("--models", nargs="+", metavar="SPEC")
    ap.add_argument("--data", nargs="+", help="--models: datasets whose test split is used")
    ap.add_argument("--limit", type=int, default=64, help="--models: scenes per dataset")
    ap.add_argument(
        "--region-tolerance",
        type=float,
        nargs="+",
        default=[],
        help="--models: also run auto with these region tolerances (0.02 = 2 %% "
        "of the prior's deepest displacement; shipped: 0.01)",
    )
    ap.add_argument("--count", type=int, default=6)
    ap.add_argument(
        "--every",
        type=int,
        default=1,
        help="--live: take every n-th placement of the plan (spread over the part)",
    )
    ap.add_argument(
        "--variant",
        type=variant,
        action="append",
        help="--live: a local-FEM variant beside the shipped one, e.g. "
        "refine=0.02,thicknesses=3,tolerance=0.01 (repeatable)",
    )
    args = ap.parse_args()
    from stmpl.machine import describe

    print(f"machine: {describe()}")
    if args.models:
        if not args.data:
            raise SystemExit("--models needs --data")
        models(args.models, args.data, args.limit, tolerances=args.region_tolerance)
    elif args.datasets:
        compare_datasets(*args.datasets)
    else:
        live(args.live, args.count, [{}] + (args.variant or []), args.every)


if __name__ == "__main__":
    main()
