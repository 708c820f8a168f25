r"""Predictors on bodies they were not trained on, body by body, and what a new body costs.

python benchmarks/bodies.py --models zoo:gnn_arm_fine zoo:linear_arm_fine \\
        --data data/bodies_test_fine data/bodies_grasps_fine [--any-body] [--limit 64]
each model on each body of each set (a folder of one dataset per body, or one
dataset): relative MEE, peak error (mean +- std), MEE in mm, the share of scenes
inside the model's envelope; then the pooled figures per set. ``--any-body`` lets a
model of one body answer on the others (``LearnedPredictor.any_body``: its inputs and
its linear prior follow each body, but it learned from one): the one-body point of the
learning curve over bodies.

python benchmarks/bodies.py --models zoo:gnn_arm_fine runs/gnn_bodies2_fine/... \
        --curve 1 3 --data data/bodies_test_fine --any-body --out reports/bodies/curve
the learning curve over bodies: each model trained on that many bodies, pooled over
the held-out ones; a markdown table and a picture (relative MEE and |peak error|
against the number of training bodies, a line per set) beside ``--out``.

python benchmarks/bodies.py --models zoo:gnn_arm_fine --first-call [--any-body]
serving a body nobody has asked for before, from cold caches (a fresh stmpl cache
folder; anny's own assets stay built): seconds to build its arm, and the first and
second prediction of a 2 cm disk on it (the first solves the linear prior's columns
on that body). Run it alone.
"""

from __future__ import annotations

import argparse
import os
import tempfile
import time
import warnings

import numpy as np

from stmpl.table import markdown


def _read(spec: str, any_body: bool):
    from stmpl.pipeline.spec import predictor_from_spec

    p = predictor_from_spec(spec)
    if any_body and hasattr(p, "any_body"):
        p.any_body = True
    return p


def _members(folder) -> list:
    from stmpl.data.dataset import Dataset, member_folders

    return [Dataset(f) for f in (member_folders(folder) or [folder])]


def _phenotype(ds) -> str:
    ph = (ds.part.source or {}).get("options", {}).get("phenotype") or {}
    t = ds.card["config"]["thickness_mm"]
    return (
        ", ".join(f"{k[:3]} {v:.2f}" for k, v in ph.items()) or "reference"
    ) + f"; {'/'.join(f'{x:g}' for x in t)} mm"


def accuracy(models: list, data: list, any_body: bool, limit: int | None) -> dict:
    """Each model on each body of each set, printed; returns ``{(spec, set): pooled}``."""
    from stmpl.pipeline.evaluate import evaluate_dataset
    from stmpl.predictor import OutsideEnvelope

    pooled = {}
    for spec in models:
        p = _read(spec, any_body)
        for folder in data:
            rows = []
            for ds in _members(folder):
                with warnings.catch_warnings():
                    warnings.simplefilter("ignore", OutsideEnvelope)
                    try:
                        r = evaluate_dataset(p, ds, "test", limit=limit)
                    except ValueError as e:  # a model of one body refuses the others
                        print(f"{spec:28s} {ds.card['name']:28s} refused: {str(e)[:90]}")
                        continue
                rows.append((r["samples"], r))
                print(
                    f"{spec:28s} {ds.card['name']:28s} n {r['samples']:4d}  rel. MEE "
                    f"{r['rel_mee'][0]:5.2f} %  peak {r['peak_err'][0]:+5.1f} +- "
                    f"{r['peak_err'][1]:4.1f} %  MEE {r['mee'][0]:.4f} mm  inside "
                    f"{r['inside_envelope'][0]:5.1f} %  ({_phenotype(ds)})",
                    flush=True,
                )
            if rows:
                w = np.array([n for n, _ in rows], float)
                rel = float(np.sum([n * r["rel_mee"][0] for n, r in rows]) / w.sum())
                peak = float(np.sum([n * r["peak_err"][0] for n, r in rows]) / w.sum())
                mee = float(np.sum([n * r["mee"][0] for n, r in rows]) / w.sum())
                print(
                    f"{spec:28s} {str(folder):28s} pooled over {len(rows)} bodies, "
                    f"{int(w.sum())} scenes: rel. MEE {rel:.2f} %, peak {peak:+.1f} %, "
                    f"MEE {mee:.4f} mm",
                    flush=True,
                )
                pooled[spec, str(folder)] = {
                    "rel_mee": rel,
                    "peak_err": peak,
                    "mee": mee,
                    "scenes": int(w.sum()),
                    "bodies": len(rows),
                }
    return pooled


def curve(models: list, counts: list, data: list, pooled: dict, out) -> None:
    """The learning curve over bodies: a table and a picture beside ``out``."""
    import pathlib

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    out = pathlib.Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    lines = []
    for n, spec in sorted(zip(counts, models)):
        cells = [
            (
                f"{pooled[spec, d]['rel_mee']:.2f} / {pooled[spec, d]['peak_err']:+.1f}"
                if (spec, d) in pooled
                else "–"
            )
            for d in data
        ]
        lines.append([n, spec, *cells])
    columns = ["training bodies", "model"]
    columns += [f"{pathlib.Path(d).name}: rel. MEE % / peak %" for d in data]
    out.with_suffix(".md").write_text(markdown(columns, lines, "rl" + "r" * len(data)))
    fig, axes = plt.subplots(1, 2, figsize=(10, 4))
    for d in data:
        pts = sorted((n, pooled[spec, d]) for n, spec in zip(counts, models) if (spec, d) in pooled)
        if not pts:
            continue
        x = [n for n, _ in pts]
        axes[0].plot(x, [r["rel_mee"] for _, r in pts], "o-", label=pathlib.Path(d).name)
        axes[1].plot(x, [abs(r["peak_err"]) for _, r in pts], "o-", label=pathlib.Path(d).name)
    for ax, what in zip(
        axes, ("relative MEE on held-out bodies, %", "|mean peak error| on held-out bodies, %")
    ):
        ax.set_xlabel("bodies trained on")
        ax.set_ylabel(what)
        ax.set_xscale("log", base=2)
        ax.set_xticks(sorted(set(counts)))
        ax.xaxis.set_major_formatter(matplotlib.ticker.FormatStrFormatter("%g"))
        ax.xaxis.set_minor_locator(matplotlib.ticker.NullLocator())
        ax.set_xlim(min(counts) / 1.4, max(counts) * 1.4)
        ax.grid(True, alpha=0.3)
        ax.set_ylim(0, 1.25 * max([line.get_ydata().max() for line in ax.get_lines()] or [1]))
    axes[0].legend(fontsize=8, loc="lower left")
    fig.suptitle("How many bodies are enough: error on bodies no model saw")
    fig.tight_layout()
    fig.savefig(out.with_suffix(".png"), dpi=120)
    print("\n".join(lines))
    print(f"wrote {out.with_suffix('.md')} and {out.with_suffix('.png')}")


def first_call(models: list, any_body: bool, seed: int = 11, bodies: int = 2) -> None:
    """Phenotypes no dataset holds, from a fresh cache: per model ``bodies`` new bodies, each
    its arm and two predictions. The process's very first body also pays the one-time imports
    and library loads (the FEM's, MKL's); the later ones show what a new body costs alone.
    """
    os.environ["STMPL_CACHE_DIR"] = tempfile.mkdtemp(prefix="stmpl-cold-")
    from stmpl import loads, tissue
    from stmpl.body.spec import part_from_spec
    from stmpl.scene import Scene

    rng = np.random.default_rng(seed)
    served = 0
    for spec in models:
        p = _read(spec, any_body)
        for _ in range(bodies):
            ph = {
                k: round(float(v), 3)
                for k, v in zip(("weight", "muscle", "height", "gender"), rng.uniform(0.2, 0.8, 4))
            }
            t0 = time.perf_counter()
            part = part_from_spec({"model": "anny", "subdivisions": 1, "phenotype": ph}, "left_arm")
            t_body = time.perf_counter() - t0
            at = int(np.argmin(np.abs(part.axial - np.median(part.axial))))
            scene = Scene(
                part, tissue.from_weight(part, ph["weight"]), loads.disk(part, at, 0.02, 0.3).force
            )
            times = []
            for _ in range(2):
                t0 = time.perf_counter()
                with warnings.catch_warnings():
                    warnings.simplefilter("ignore")
                    p.predict(scene)
                times.append(time.perf_counter() - t0)
            which = "the process's first body" if served == 0 else "another new body"
            served += 1
            print(
                f"{spec}: {which} {ph}: arm {t_body:.2f} s, first prediction "
                f"{times[0]:.2f} s, second {times[1] * 1e3:.1f} ms; first call in all "
                f"{t_body + times[0]:.2f} s",
                flush=True,
            )


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--models", nargs="+", required=True)
    ap.add_argument("--data", nargs="*", default=[])
    ap.add_argument("--any-body", action="store_true")
    ap.add_argument("--limit", type=int)
    ap.add_argument("--first-call", action="store_true")
    ap.add_argument(
        "--curve",
        type=int,
        nargs="+",
        metavar="N",
        help="bodies each model was trained on (one per --models): a curve",
    )
    ap.add_argument("--out", default="reports/bodies/curve", help="the curve's files, no suffix")
    a = ap.parse_args(argv)
    if a.curve and len(a.curve) != len(a.models):
        ap.error("--curve needs one number of bodies per model")
    from stmpl.machine import describe

    print(f"machine: {describe()}")
    if a.first_call:
        first_call(a.models, a.any_body)
    if a.data:
        pooled = accuracy(a.models, a.data, a.any_body, a.limit)
        if a.curve:
            curve(a.models, a.curve, a.data, pooled, a.out)


if __name__ == "__main__":
    main()
