"""The FEM's kinematics compiled and in NumPy, side by side: the deformation gradient at every
quadrature point and the inverse of F, on arrays the size of a grip's mesh.

    python benchmarks/fem_kinematics.py [--elements 57000] [--repeat 20]

A grip of the grip set (configs/data/forearm_grips.yaml) meshes the forearm with some 57k
quadratic tetrahedra (10 nodes, 4 quadrature points each); the solver computes F and its
inverse at every residual and tangent, hundreds of times a force. The arrays here are that
size, filled with a small random displacement and random shape-function gradients (the
kernels' cost does not depend on the values). Run it alone, on one thread
(``OMP_NUM_THREADS=1 NUMBA_NUM_THREADS=1``), as the dataset's workers run.
"""

from __future__ import annotations

import argparse

import numpy as np
from _timing import median_time

from fem.kinematics import _kernels, deformation_gradient, inv3
from stmpl.machine import describe
from stmpl.table import header, row


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--elements", type=int, default=57000, help="quadratic tetrahedra")
    ap.add_argument("--repeat", type=int, default=20, help="timed calls of each (median)")
    args = ap.parse_args()

    if _kernels() is None:
        raise SystemExit("numba is not installed: there is no compiled way to time")
    rng = np.random.default_rng(0)
    T, Q, n = args.elements, 4, 10
    nodes = 14 * T // 10  # a quadratic tetrahedral mesh has about 1.4 nodes an element
    conn = rng.integers(0, nodes, (T, n))
    G = rng.normal(0.0, 300.0, (T, Q, n, 3))  # 1/m: edges of a few mm
    u = rng.normal(0.0, 1e-5, (nodes, 3))  # m
    F = deformation_gradient(u, conn, G).reshape(-1, 3, 3)

    rows = []
    for what, fast, slow in (
        (
            "deformation gradient (T, 4, 3, 3)",
            lambda: deformation_gradient(u, conn, G),
            lambda: deformation_gradient(u, conn, G, compiled=False),
        ),
        ("inverse and det of F", lambda: inv3(F), lambda: inv3(F, compiled=False)),
    ):
        a = median_time(fast, args.repeat, warmup=2)
        b = median_time(slow, args.repeat, warmup=2)
        rows.append((what, a, b))
    print(f"{T} quadratic tetrahedra, {Q} points each; median of {args.repeat} calls")
    print(describe())
    print(header(["", "compiled ms", "NumPy ms", "ratio"], "lrrr"))
    for what, a, b in rows:
        print(row([what, f"{1e3 * a:.1f}", f"{1e3 * b:.1f}", f"{b / a:.1f}"]))


if __name__ == "__main__":
    main()
