"""Predictors on bodies they were not trained on, body by body, and what a new body costs.

    python benchmarks/bodies.py --models zoo:gnn_arm_fine zoo:linear_arm_fine \\
        --data data/bodies_test_fine data/bodies_grasps_fine [--any-body] [--limit 64]
        each model on each body of each set (a folder of one dataset per body, or one
        dataset): relative MEE, peak error (mean +- std), MEE in mm, the share of scenes
        inside the model's envelope; then the pooled figures per set. ``--any-body`` lets a
        model of one body answer on the others (``LearnedPredictor.any_body``: its inputs and
        its linear prior follow each body, but it learned from one): the one-body point of the
        learning curve over bodies.

    python benchmarks/bodies.py --models zoo:gnn_arm_fine --first-call [--any-body]
        serving a body nobody has asked for before, from cold caches (a fresh stmpl cache
        folder; anny's own assets stay built): seconds to build its arm, and the first and
        second prediction of a 2 cm disk on it (the first solves the linear prior's columns
        on that body). Run it alone.
"""

from __future__ import annotations

import argparse
import os
import platform
import tempfile
import time
import warnings

import numpy as np


def _read(spec: str, any_body: bool):
    from stmpl.spec import predictor_from_spec

    p = predictor_from_spec(spec)
    if any_body and hasattr(p, "any_body"):
        p.any_body = True
    return p


def _members(folder) -> list:
    from stmpl.dataset import Dataset, member_folders

    return [Dataset(f) for f in (member_folders(folder) or [folder])]


def _phenotype(ds) -> str:
    ph = (ds.part.source or {}).get("options", {}).get("phenotype") or {}
    t = ds.card["config"]["thickness_mm"]
    return (", ".join(f"{k[:3]} {v:.2f}" for k, v in ph.items()) or "reference") + \
        f"; {'/'.join(f'{x:g}' for x in t)} mm"


def accuracy(models: list, data: list, any_body: bool, limit: int | None) -> None:
    from stmpl.evaluate import evaluate_dataset
    from stmpl.predictor import OutsideEnvelope

    for spec in models:
        p = _read(spec, any_body)
        for folder in data:
            rows = []
            for ds in _members(folder):
                with warnings.catch_warnings():
                    warnings.simplefilter("ignore", OutsideEnvelope)
                    try:
                        r = evaluate_dataset(p, ds, "test", limit=limit)
                    except ValueError as e:         # a model of one body refuses the others
                        print(f"{spec:28s} {ds.card['name']:28s} refused: {str(e)[:90]}")
                        continue
                rows.append((r["samples"], r))
                print(f"{spec:28s} {ds.card['name']:28s} n {r['samples']:4d}  rel. MEE "
                      f"{r['rel_mee'][0]:5.2f} %  peak {r['peak_err'][0]:+5.1f} +- "
                      f"{r['peak_err'][1]:4.1f} %  MEE {r['mee'][0]:.4f} mm  inside "
                      f"{r['inside_envelope'][0]:5.1f} %  ({_phenotype(ds)})", flush=True)
            if rows:
                w = np.array([n for n, _ in rows], float)
                rel = float(np.sum([n * r["rel_mee"][0] for n, r in rows]) / w.sum())
                peak = float(np.sum([n * r["peak_err"][0] for n, r in rows]) / w.sum())
                mee = float(np.sum([n * r["mee"][0] for n, r in rows]) / w.sum())
                print(f"{spec:28s} {str(folder):28s} pooled over {len(rows)} bodies, "
                      f"{int(w.sum())} scenes: rel. MEE {rel:.2f} %, peak {peak:+.1f} %, "
                      f"MEE {mee:.4f} mm", flush=True)


def first_call(models: list, any_body: bool, seed: int = 11) -> None:
    """A phenotype no dataset holds, its arm and two predictions, from a fresh cache."""
    os.environ["STMPL_CACHE_DIR"] = tempfile.mkdtemp(prefix="stmpl-cold-")
    from stmpl import loads, tissue
    from stmpl.body.spec import part_from_spec
    from stmpl.scene import Scene

    rng = np.random.default_rng(seed)
    for spec in models:
        p = _read(spec, any_body)
        ph = {k: round(float(v), 3) for k, v in zip(
            ("weight", "muscle", "height", "gender"), rng.uniform(0.2, 0.8, 4))}
        t0 = time.perf_counter()
        part = part_from_spec({"model": "anny", "subdivisions": 1, "phenotype": ph}, "left_arm")
        t_body = time.perf_counter() - t0
        at = int(np.argmin(np.abs(part.axial - np.median(part.axial))))
        scene = Scene(part, tissue.from_weight(part, ph["weight"]),
                      loads.disk(part, at, 0.02, 0.3).force)
        times = []
        for _ in range(2):
            t0 = time.perf_counter()
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                p.predict(scene)
            times.append(time.perf_counter() - t0)
        print(f"{spec}: new body {ph}: arm {t_body:.2f} s, first prediction {times[0]:.2f} s, "
              f"second {times[1] * 1e3:.1f} ms; first call in all {t_body + times[0]:.2f} s",
              flush=True)


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--models", nargs="+", required=True)
    ap.add_argument("--data", nargs="*", default=[])
    ap.add_argument("--any-body", action="store_true")
    ap.add_argument("--limit", type=int)
    ap.add_argument("--first-call", action="store_true")
    a = ap.parse_args(argv)
    print(f"machine: {platform.machine()}, {os.cpu_count()} cores; torch threads "
          f"{__import__('torch').get_num_threads()}")
    if a.first_call:
        first_call(a.models, a.any_body)
    if a.data:
        accuracy(a.models, a.data, a.any_body, a.limit)


if __name__ == "__main__":
    main()
