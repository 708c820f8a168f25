"""Preconditioned conjugate gradients for Newton's steps, with a factorised earlier tangent as
the preconditioner (an inexact Newton method: the step solves the current tangent, the
factorisation is only kept while it preconditions well).
"""

from __future__ import annotations

import functools
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from stmpl.jit import njit


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
    ``x`` ``(n,)`` or ``(n, k)``. A block of :data:`BLOCK` columns or more is multiplied by a
    compiled kernel over the whole matrix's rows (both cores; SciPy's product runs on one).
    """
    made = {}  # the stored triangle's transpose and diagonal, the whole matrix: at first use

    def lower() -> tuple[sp.csr_matrix, np.ndarray]:
        if "KT" not in made:
            made["KT"], made["diagonal"] = K.T.tocsr(), K.diagonal()
        return made["KT"], made["diagonal"]

    def matvec(x: np.ndarray) -> np.ndarray:
        kernel = _block_kernel() if x.ndim == 2 and x.shape[1] >= BLOCK else None
        if kernel is not None:
            if "whole" not in made:
                if upper:
                    KT, diagonal = lower()
                    W = (K + KT - sp.diags(diagonal)).tocsr()
                else:
                    W = K.tocsr()
                W.sort_indices()
                made["whole"] = W
            W = made["whole"]
            y = np.empty(x.shape)
            kernel(W.indptr, W.indices, W.data, np.ascontiguousarray(x, dtype=float), y)
            return y
        if not upper:
            return K @ x
        single = _upper_kernel() if x.ndim == 1 else None
        if single is not None:  # one pass over the triangle: no transpose made
            y = np.empty(len(x))
            single(K.indptr, K.indices, K.data, np.ascontiguousarray(x, dtype=float), y)
            return y
        KT, diagonal = lower()
        return K @ x + KT @ x - (diagonal * x.T).T

    return matvec


@functools.cache
def _upper_kernel():
    """``kernel(indptr, indices, data, x, y)``: ``y = K x`` for a symmetric ``K`` stored as its
    upper triangle (CSR), in one pass: each stored ``K_ij`` adds ``K_ij x_j`` to ``y_i`` and,
    off the diagonal, ``K_ij x_i`` to ``y_j``. On a grip's tangent (9M stored entries) this
    spares making the triangle's transpose (0.17 s a tangent) for Newton's CG solves; ``None``
    when Numba is absent.
    """
    jit = njit()
    if jit is None:
        return None

    @jit
    def kernel(indptr, indices, data, x, y):  # pragma: no cover - compiled
        y[:] = 0.0
        for i in range(len(indptr) - 1):
            xi, acc = x[i], 0.0
            for p in range(indptr[i], indptr[i + 1]):
                j, v = indices[p], data[p]
                acc += v * x[j]
                if j != i:
                    y[j] += v * xi
            y[i] += acc

    return kernel


BLOCK = 8
"""Columns from which a block product goes to the compiled kernel."""


@functools.cache
def _block_kernel():
    """``kernel(indptr, indices, data, X, Y)``: ``Y = K X`` for a CSR ``K`` and row-major
    ``X`` ``(n, k)``, rows in parallel, the GIL released (a caller's other threads run on);
    ``None`` when Numba is absent.
    """
    jit = njit(parallel=True)
    if jit is None:
        return None
    from numba import prange  # deferred: Numba is there (jit is), and imported by now

    @jit
    def kernel(indptr, indices, data, X, Y):  # pragma: no cover - compiled
        k = X.shape[1]
        for i in prange(len(indptr) - 1):
            acc = np.zeros(k)
            for p in range(indptr[i], indptr[i + 1]):
                v = data[p]
                j = indices[p]
                for c in range(k):
                    acc[c] += v * X[j, c]
            for c in range(k):
                Y[i, c] = acc[c]

    return kernel


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
