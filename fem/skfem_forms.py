"""The Neo-Hookean residual and tangent written as scikit-fem forms: the readable reference the
fast kernel in :mod:`fem.solver` is checked against (tests) and timed against (benchmark).

With ``F = I + grad u``, ``H = F^-1``, ``J = det F``::

    r(v)     = int P(F) : grad v,     P = mu (F - H^T) + lam ln J H^T
    a(du, v) = int (A : grad du) : grad v,
    A : dF   = mu dF + lam tr(H dF) H^T + (mu - lam ln J) H^T dF^T H^T
"""

from __future__ import annotations

import numpy as np


def neo_hookean_forms(mu: float, lam: float):
    """``(residual LinearForm, tangent BilinearForm)``; pass the current displacement as
    ``prev=basis.interpolate(u)``.
    """
    import skfem  # deferred: the reference assembly only
    from skfem.helpers import (
        ddot,
        det,
        eye,
        grad,
        inv,
        mul,
        trace,
        transpose,
    )  # deferred: the reference assembly only

    def parts(w):
        g = grad(w["prev"])  # (3, 3, elements, points)
        F = eye(np.ones_like(g[0, 0]), 3) + g
        return F, inv(F), np.log(det(F))

    @skfem.LinearForm
    def residual(v, w):
        F, H, lnJ = parts(w)
        return ddot(mu * (F - transpose(H)) + lam * lnJ * transpose(H), grad(v))

    @skfem.BilinearForm
    def tangent(du, v, w):
        F, H, lnJ = parts(w)
        dF = grad(du)
        AdF = (
            mu * dF
            + lam * trace(mul(H, dF)) * transpose(H)
            + (mu - lam * lnJ) * mul(transpose(H), mul(transpose(dF), transpose(H)))
        )
        return ddot(AdF, grad(v))

    return residual, tangent


def assemble(
    nodes: np.ndarray, tets: np.ndarray, u: np.ndarray, mu: float, lam: float, order: int = 1
):
    """scikit-fem's ``(residual (3M,), tangent CSR)`` over all DOFs in its own numbering, for
    P1 (``u`` ``(M, 3)``) or P2 (``u`` in scikit-fem's DOF order) tetrahedra.
    """
    import skfem  # deferred: the reference assembly only

    mesh = skfem.MeshTet(nodes.T, tets.T)
    el = skfem.ElementTetP1() if order == 1 else skfem.ElementTetP2()
    basis = skfem.Basis(mesh, skfem.ElementVector(el))
    residual, tangent = neo_hookean_forms(mu, lam)
    prev = basis.interpolate(np.asarray(u, dtype=float).reshape(-1))
    return skfem.asm(residual, basis, prev=prev), skfem.asm(tangent, basis, prev=prev).tocsr()
