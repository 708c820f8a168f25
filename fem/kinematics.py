"""Kinematics at the quadrature points: the deformation gradient ``F = I + sum_a u_a (x) grad N_a``
of a displacement, and the determinant and inverse of ``F``.

The deformation gradient and the inverse are compiled with Numba where it is installed (one
pass over the elements, no temporaries: on arrays of a grip's 57k quadratic elements about 5
and 9 times as fast as NumPy's batched products, `benchmarks/fem_kinematics.py`), NumPy
otherwise; the two agree to rounding, and a test holds them to it. The laws invert ``F`` once
per layer at every residual and tangent, so these run hundreds of times a force.
"""

from __future__ import annotations

import functools

import numpy as np

from stmpl.jit import njit


def det3(F: np.ndarray) -> np.ndarray:
    """``(T,)`` determinants of ``(T, 3, 3)`` matrices (closed form, faster than LAPACK here)."""
    return (
        F[:, 0, 0] * (F[:, 1, 1] * F[:, 2, 2] - F[:, 1, 2] * F[:, 2, 1])
        - F[:, 0, 1] * (F[:, 1, 0] * F[:, 2, 2] - F[:, 1, 2] * F[:, 2, 0])
        + F[:, 0, 2] * (F[:, 1, 0] * F[:, 2, 1] - F[:, 1, 1] * F[:, 2, 0])
    )


def inv3(F: np.ndarray, compiled: bool = True) -> tuple[np.ndarray, np.ndarray]:
    """``(F^-1 (T, 3, 3), det F (T,))`` by cofactors; ``compiled=False``: NumPy's way even
    where Numba is installed (to check the kernel against).
    """
    kernels = _kernels() if compiled else None
    if kernels is not None and F.dtype == np.float64:
        return kernels[1](np.ascontiguousarray(F))
    C = np.empty_like(F)
    C[:, 0, 0] = F[:, 1, 1] * F[:, 2, 2] - F[:, 1, 2] * F[:, 2, 1]
    C[:, 0, 1] = F[:, 0, 2] * F[:, 2, 1] - F[:, 0, 1] * F[:, 2, 2]
    C[:, 0, 2] = F[:, 0, 1] * F[:, 1, 2] - F[:, 0, 2] * F[:, 1, 1]
    C[:, 1, 0] = F[:, 1, 2] * F[:, 2, 0] - F[:, 1, 0] * F[:, 2, 2]
    C[:, 1, 1] = F[:, 0, 0] * F[:, 2, 2] - F[:, 0, 2] * F[:, 2, 0]
    C[:, 1, 2] = F[:, 0, 2] * F[:, 1, 0] - F[:, 0, 0] * F[:, 1, 2]
    C[:, 2, 0] = F[:, 1, 0] * F[:, 2, 1] - F[:, 1, 1] * F[:, 2, 0]
    C[:, 2, 1] = F[:, 0, 1] * F[:, 2, 0] - F[:, 0, 0] * F[:, 2, 1]
    C[:, 2, 2] = F[:, 0, 0] * F[:, 1, 1] - F[:, 0, 1] * F[:, 1, 0]
    J = F[:, 0, 0] * C[:, 0, 0] + F[:, 0, 1] * C[:, 1, 0] + F[:, 0, 2] * C[:, 2, 0]
    return C / J[:, None, None], J


def deformation_gradient(
    u: np.ndarray, conn: np.ndarray, G: np.ndarray, compiled: bool = True
) -> np.ndarray:
    """``(T, Q, 3, 3)`` ``F = I + sum_a u_a (x) grad N_a`` at the quadrature points, for nodal
    displacement ``u`` ``(n_all, 3)`` (m), the elements' nodes ``conn`` ``(T, n)`` and the shape
    functions' gradients ``G`` ``(T, Q, n, 3)`` (1/m); ``compiled`` as for :func:`inv3`.
    """
    kernels = _kernels() if compiled else None
    if kernels is not None and u.dtype == np.float64 and G.dtype == np.float64:
        return kernels[0](np.ascontiguousarray(u), conn, np.ascontiguousarray(G))
    ue = u[conn].transpose(0, 2, 1)[:, None]  # (T, 1, 3, n)
    return np.eye(3) + np.matmul(ue, G)


@functools.lru_cache(maxsize=1)
def _kernels():
    """``(deformation gradient, inverse)`` compiled by Numba (cached on disk), or ``None``."""
    jit = njit(error_model="numpy")
    if jit is None:
        return None

    @jit
    def gradient(u, conn, G):  # pragma: no cover - compiled
        T, Q, n, _ = G.shape
        F = np.zeros((T, Q, 3, 3))
        for t in range(T):
            for q in range(Q):
                for i in range(3):
                    F[t, q, i, i] = 1.0
                for a in range(n):
                    v = conn[t, a]
                    for i in range(3):
                        ui = u[v, i]
                        for j in range(3):
                            F[t, q, i, j] += ui * G[t, q, a, j]
        return F

    @jit
    def inverse(F):  # pragma: no cover - compiled
        m = F.shape[0]
        out, J = np.empty_like(F), np.empty(m)
        for k in range(m):
            a, b, c = F[k, 0, 0], F[k, 0, 1], F[k, 0, 2]
            d, e, f = F[k, 1, 0], F[k, 1, 1], F[k, 1, 2]
            g, h, i = F[k, 2, 0], F[k, 2, 1], F[k, 2, 2]
            c00, c10, c20 = e * i - f * h, f * g - d * i, d * h - e * g
            det = a * c00 + b * c10 + c * c20
            out[k, 0, 0], out[k, 0, 1], out[k, 0, 2] = c00, c * h - b * i, b * f - c * e
            out[k, 1, 0], out[k, 1, 1], out[k, 1, 2] = c10, a * i - c * g, c * d - a * f
            out[k, 2, 0], out[k, 2, 1], out[k, 2, 2] = c20, b * g - a * h, a * e - b * d
            for r in range(3):
                for s in range(3):
                    out[k, r, s] /= det
            J[k] = det
        return out, J

    return gradient, inverse
