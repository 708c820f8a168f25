"""The linear compliance (Green's) operator of a tissue shell: the small-strain displacement of
every part vertex under a unit normal force on each vertex, precomputed once by FEM.

For a load ``F`` ``(N,)`` (N per vertex, along the inward normal, spread as a traction exactly
as the ground truth spreads it) the linear response is ``u_i = sum_j G_ij F_j`` with
``G`` ``(N, N, 3)`` in m/N. It is the tangent of the Neo-Hookean solve at rest, so it is exact in
the limit of light loads and drifts from the FEM as strains grow; the classical way to make FEM
real-time (condensation onto the loaded surface), and a prior the learned models correct.

The mesh is the resolution's, refined over the whole skin (the ground truth refines only near the
load, which every vertex is here). One factorisation, then ``N`` right-hand sides in blocks.
"""

from __future__ import annotations

import numpy as np

from fem.material import material as make_material
from fem.mesh import shell_mesh
from fem.simulate import resolution
from fem.solver import Solver, SolverOptions
from stmpl.body.part import BodyPart


def compliance(part: BodyPart, thickness: float | np.ndarray, res="reference", material=None,
               options: SolverOptions | None = None, block: int = 64,
               progress=None) -> np.ndarray:
    """``(N, N, 3)`` compliance ``G`` (m/N): ``G[i, j]`` is vertex ``i``'s displacement under a
    unit normal force on vertex ``j`` of a layer of ``thickness`` (m, a scalar or ``(N,)``).

    ``material``: a material object or its dict (its tangent at rest is used, so Neo-Hookean and
    linear give the same operator); ``options``: the ground truth's :class:`SolverOptions` (load
    mode, fixed rims, linear solver); ``progress``: a callable taking the number of columns done.
    Raises ``ArithmeticError`` (from the factorisation) if the stiffness is not positive definite.
    """
    n = part.n_vertices
    t = np.broadcast_to(np.asarray(thickness, dtype=float), (n,)).copy()
    r = resolution(res)
    mat = make_material(**material) if isinstance(material, dict) else material
    mesh = shell_mesh(part, t, layers=r.layers, subdivisions=r.subdivisions)
    solver = Solver(mesh, mat, options=options, order=r.order)
    u0 = np.zeros((solver.n_all, 3))
    _, K = solver.assemble(u0, u0)
    solver.linear.factor(K)
    G = np.zeros((n, n, 3))
    nodes = mesh.part_nodes
    for lo in range(0, n, block):
        cols = np.arange(lo, min(lo + block, n))
        B = np.empty((len(solver.free), len(cols)))
        for k, j in enumerate(cols):
            e = np.zeros(n)
            e[j] = 1.0
            B[:, k] = solver.external_forces(e).ravel()[solver.free]
        X = solver.linear.solve(B)
        u = np.zeros((solver.n_all * 3, len(cols)))
        u[solver.free] = X
        G[:, cols] = u.reshape(solver.n_all, 3, len(cols))[nodes].transpose(0, 2, 1)
        if progress is not None:
            progress(len(cols))
    if not np.all(np.isfinite(G)):
        raise ArithmeticError("the compliance operator has non-finite entries")
    return G


def sparsify(G: np.ndarray, tol: float = 1e-3) -> tuple[np.ndarray, np.ndarray, float]:
    """The pattern of ``G`` ``(L, N, N, 3)`` (L thickness levels) worth keeping: pairs ``(i, j)``
    where ``|G_ij|`` reaches ``tol`` times the level's largest entry at some level.

    Returns ``(index (2, nnz) [i; j], values (L, nnz, 3), dropped)``, ``dropped`` the largest
    left-out ``|G_ij|`` relative to its level's largest (<= ``tol``)."""
    mag = np.linalg.norm(G, axis=-1)                                  # (L, N, N)
    rel = mag / mag.reshape(len(G), -1).max(1)[:, None, None]
    keep = (rel >= tol).any(0)
    i, j = np.nonzero(keep)
    dropped = float(np.where(keep[None], 0.0, rel).max())
    return np.stack([i, j]), G[:, i, j], dropped
