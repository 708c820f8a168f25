"""The linear FEM on demand against the stored operator: what a scene costs when only the columns
it loads are solved (on the patch they move), cold, warm in memory and from the disk cache, and
how far those columns are from the whole part's.

    python benchmarks/linear_on_demand.py [--subdivisions 1] [--thickness-mm 7.5] [--whole]

For each load (a 2 cm disk, an ellipse, a band, anny's right hand grasping the forearm) on the
left arm: the loaded vertices, the first call's time (a new store, empty cache: the patch's
mesh, factorisation and columns), a second call on the same store (memory) and a new store
reading the disk cache. ``--whole`` also solves the same columns on the whole part and prints the
largest difference relative to the load's deepest displacement (slow on the fine arm: about a
minute for the mesh and the factorisation). Run it alone: the times are wall-clock.
"""

from __future__ import annotations

import argparse
import os
import tempfile
import time

import numpy as np

from stmpl.table import header, row

SETUP = {
    "material": {"name": "neo_hookean", "E": 1000.0, "nu": 0.4},
    "resolution": "reference",
    "solver": None,
}


def loads(part):
    from stmpl import loads as L
    from stmpl.contact.hand import Hand, grasp
    from stmpl.contact.pressing import contact

    g = grasp(part, Hand(phenotype={"height": 0.5}), 0.7, 0.0, "whole", 0.002)
    return {
        "disk 2 cm": L.disk(part, uv=(0.3, 0.5), radius=0.02, total=0.3).force,
        "ellipse 4x2 cm": L.ellipse(part, uv=(0.6, 0.4), semi_axes=(0.04, 0.02), total=0.3).force,
        "band 3 cm": L.band(part, at=0.5, width=0.03, total=0.3).force,
        "grasp (whole hand)": contact(part, [g.pressing(0.3, "hand")]).force,
    }


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--subdivisions", type=int, default=1)
    ap.add_argument("--thickness-mm", type=float, default=7.5)
    ap.add_argument("--whole", action="store_true", help="compare with whole-part columns")
    args = ap.parse_args(argv)
    os.environ["STMPL_CACHE_DIR"] = tempfile.mkdtemp(prefix="stmpl-ondemand-")

    from fem.compliance import ColumnStore, compliance
    from fem.material import material
    from stmpl.body.spec import part_from_spec
    from stmpl.machine import describe

    part = part_from_spec({"model": "anny", "subdivisions": args.subdivisions}, "left_arm")
    t = args.thickness_mm * 1e-3
    print(
        f"left arm, {args.subdivisions} subdivision(s): {part.n_vertices} vertices; "
        f"layer {args.thickness_mm:g} mm; {describe()}"
    )
    columns = ["load", "loaded vertices", "patch vertices", "cold s", "memory ms", "disk cache ms"]
    columns += ["whole-part s", "max diff %"] if args.whole else []
    print(header(columns, "l" + "r" * (len(columns) - 1)))
    for name, f in loads(part).items():
        cols = np.flatnonzero(f > 0)
        store = ColumnStore(part, SETUP, [t])
        t0 = time.perf_counter()
        G = store.columns(0, cols)
        cold = time.perf_counter() - t0
        t0 = time.perf_counter()
        store.columns(0, cols)
        mem = time.perf_counter() - t0
        t0 = time.perf_counter()
        ColumnStore(part, SETUP, [t]).columns(0, cols)
        disk = time.perf_counter() - t0
        u = np.einsum("nkc,k->nc", G, f[cols])
        cells = [name, len(cols), store.log[-1]["vertices"], f"{cold:.1f}"]
        cells += [f"{1e3 * mem:.1f}", f"{1e3 * disk:.0f}"]
        if args.whole:
            t0 = time.perf_counter()
            W = compliance(part, t, "reference", material(**SETUP["material"]), columns=cols)
            tw = time.perf_counter() - t0
            uw = np.einsum("nkc,k->nc", W, f[cols])
            diff = np.linalg.norm(u - uw, axis=1).max() / np.linalg.norm(uw, axis=1).max()
            cells += [f"{tw:.1f}", f"{100 * diff:.3f}"]
        print(row(cells), flush=True)


if __name__ == "__main__":
    main()
