"""Preconditioned conjugate gradients for Newton's steps, with a factorised earlier tangent as
the preconditioner (an inexact Newton method: the step solves the current tangent, the
factorisation is only kept while it preconditions well).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp


@dataclass(frozen=True)
class Krylov:
    """A preconditioned CG solve's outcome: ``x`` (``None`` when it failed), the iterations it
    took, and why it failed (``""`` when it met its tolerance).
    """

    x: np.ndarray | None
    iterations: int
    reason: str = ""


def symmetric_matvec(K: sp.csr_matrix, upper: bool) -> Callable[[np.ndarray], np.ndarray]:
    """``x -> K x`` for a symmetric ``K`` stored whole or, ``upper``, as its upper triangle;
    ``x`` ``(n,)`` or ``(n, k)``.
    """
    if not upper:
        return K.__matmul__
    diagonal = K.diagonal()
    KT = K.T.tocsr()
    return lambda x: K @ x + KT @ x - (diagonal * x.T).T


def pcg(
    matvec: Callable[[np.ndarray], np.ndarray],
    precondition: Callable[[np.ndarray], np.ndarray],
    b: np.ndarray,
    rtol: float,
    maxiter: int,
) -> Krylov:
    """Solve ``A x = b`` (``(n,)``) for a symmetric ``A`` to ``|b - A x| <= rtol |b|`` by
    conjugate gradients preconditioned with ``precondition`` (an approximate ``A^-1``, symmetric
    positive definite). Fails, saying why, on a direction of non-positive curvature (``A`` is not
    positive definite there), a non-finite value, or ``maxiter`` iterations without convergence.
    """
    bnorm = float(np.linalg.norm(b))
    if bnorm == 0.0:
        return Krylov(np.zeros_like(b), 0)
    x = precondition(b)
    r = b - matvec(x)
    z = precondition(r)
    p = z.copy()
    rz = float(r @ z)
    for it in range(1, maxiter + 1):
        if not np.isfinite(rz):
            return Krylov(None, it, "a non-finite value")
        if np.linalg.norm(r) <= rtol * bnorm:
            return Krylov(x, it)
        Ap = matvec(p)
        curvature = float(p @ Ap)
        if not curvature > 0:
            return Krylov(None, it, "a direction of non-positive curvature")
        alpha = rz / curvature
        x += alpha * p
        r -= alpha * Ap
        z = precondition(r)
        rz, rz_old = float(r @ z), rz
        p = z + (rz / rz_old) * p
    if np.linalg.norm(r) <= rtol * bnorm:
        return Krylov(x, maxiter)
    return Krylov(None, maxiter, f"no convergence in {maxiter} iterations")
