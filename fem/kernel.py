"""The tangent's element matrices summed into its CSR data, two ways: a compiled kernel (Numba;
every element matrix's upper entries summed over its quadrature points, then added into the
data) and its NumPy twin, used
without Numba and to check the kernel.
"""

from __future__ import annotations

import functools
from collections.abc import Callable
from typing import NamedTuple

import numpy as np


def element_data(g, GG, aW, bW, cW, local, pos, sel, nnz: int, full=None) -> np.ndarray:
    """The tangent's CSR data (``(nnz,)``) with NumPy, from ``g`` ``(T, Q, n, 3)``
    (``H^T grad N``), ``GG`` ``(T, Q, n, n)``, the weighted tangent parts ``aW, bW, cW``
    ``(T, Q)``, the element entries ``local = (A, I, B, K)`` and their places ``pos`` among the
    data (``sel`` selects the entries that have one). ``full = (f, dW, eW)`` adds the long
    form's terms ``dW f_ai f_bk + eW (f_ai g_bk + g_ai f_bk)``, ``f`` ``(T, Q, n, 3)`` being
    ``F grad N``.
    """
    A, I, B, Kc = local
    vals = 0.0
    for q in range(g.shape[1]):
        gq = g[:, q]
        vals = vals + (
            bW[:, q, None] * gq[:, A, I] * gq[:, B, Kc]
            + cW[:, q, None] * gq[:, A, Kc] * gq[:, B, I]
            + (I == Kc) * (aW[:, q, None] * GG[:, q][:, A, B])
        )
        if full is not None:
            f, dW, eW = full
            fq = f[:, q]
            vals = vals + (
                dW[:, q, None] * fq[:, A, I] * fq[:, B, Kc]
                + eW[:, q, None] * (fq[:, A, I] * gq[:, B, Kc] + gq[:, A, I] * fq[:, B, Kc])
            )
    flat = vals.ravel()
    data = np.zeros(nnz)
    for p, s in zip(pos, sel):
        data += np.bincount(p, weights=flat[s], minlength=nnz)
    return data


def make_kernel():
    """A Numba kernel that adds the upper entries of every element matrix,
    ``K_aibk = sum_q (aW d_ik G_a.G_b + bW g_ai g_bk + cW g_ak g_bi)``, to the CSR data: each
    element's entries summed over its quadrature points first, then added once (4x faster than
    the NumPy path here); ``None`` when Numba is absent.
    """
    both = _element_kernel()
    if both is None:
        return None

    def kernel(g, GG, aW, bW, cW, pos, data):
        both(g, g, GG, aW, bW, cW, aW, aW, False, pos, data)  # f, dW, eW unread

    return kernel


def make_full_kernel():
    """The compiled kernel of the long form (laws of ``I1`` and ``J``): as
    :func:`make_kernel`'s, plus ``dW f_ai f_bk + eW (f_ai g_bk + g_ai f_bk)`` with ``f`` the
    gradients mapped by ``F``; ``None`` when Numba is absent.
    """
    both = _element_kernel()
    if both is None:
        return None

    def kernel(g, f, GG, aW, bW, cW, dW, eW, pos, data):
        both(g, f, GG, aW, bW, cW, dW, eW, True, pos, data)

    return kernel


@functools.cache
def _element_kernel():
    """The compiled kernel behind :func:`make_kernel` (``long`` False) and
    :func:`make_full_kernel` (``long`` True); ``None`` when Numba is absent.
    """
    try:
        from numba import njit  # deferred: compiles the FEM's kernels
    except ImportError:
        return None

    @njit(cache=True, nogil=True)
    def kernel(g, f, GG, aW, bW, cW, dW, eW, long, pos, data):  # pragma: no cover - compiled
        T, Q, n = g.shape[0], g.shape[1], g.shape[2]
        m = 3 * n
        ke = np.zeros(m * (m + 1) // 2)  # one element's upper entries, summed over its points
        for t in range(T):
            ke[:] = 0.0
            for qp in range(Q):
                a, b, c, d, h = aW[t, qp], bW[t, qp], cW[t, qp], dW[t, qp], eW[t, qp]
                gt, ft, Gt = g[t, qp], f[t, qp], GG[t, qp]
                e = 0
                for p in range(m):
                    A, i = p // 3, p % 3
                    gai = gt[A, i]
                    fai = ft[A, i] if long else 0.0
                    for q in range(p, m):
                        B, k = q // 3, q % 3
                        gbk = gt[B, k]
                        v = b * gai * gbk + c * gt[A, k] * gt[B, i]
                        if long:
                            fbk = ft[B, k]
                            v += d * fai * fbk + h * (fai * gbk + gai * fbk)
                        if i == k:
                            v += a * Gt[A, B]
                        ke[e] += v
                        e += 1
            for e in range(len(ke)):
                j = pos[t, e]
                if j >= 0:
                    data[j] += ke[e]

    return kernel


def outer_data(beta, coef, pos, sel, local, nnz: int) -> np.ndarray:
    """The CSR data (``(nnz,)``) of every element's rank-one matrix ``coef_t beta_t beta_t^T``
    with NumPy: ``beta`` ``(T, 3 n)`` (entry ``3 a + i``: node ``a``, component ``i``),
    ``coef`` ``(T,)``; ``local``, ``pos``, ``sel`` as in :func:`element_data`.
    """
    A, I, B, Kc = local
    vals = (coef[:, None] * beta[:, 3 * A + I] * beta[:, 3 * B + Kc]).ravel()
    data = np.zeros(nnz)
    for p, s in zip(pos, sel):
        data += np.bincount(p, weights=vals[s], minlength=nnz)
    return data


def make_outer_kernel():
    """A Numba kernel adding every element's ``coef_t beta_t beta_t^T`` (upper entries) to the
    CSR data; ``None`` when Numba is absent.
    """
    try:
        from numba import njit  # deferred: compiles the FEM's kernels
    except ImportError:
        return None

    @njit(cache=True, nogil=True)
    def kernel(beta, coef, pos, data):  # pragma: no cover - compiled
        T, m = beta.shape
        for t in range(T):
            e = 0
            for p in range(m):
                bp = coef[t] * beta[t, p]
                for q in range(p, m):
                    j = pos[t, e]
                    e += 1
                    if j >= 0:
                        data[j] += bp * beta[t, q]

    return kernel


class Kernels(NamedTuple):
    """The compiled kernels (each ``None`` without Numba: the NumPy path instead)."""

    element: Callable | None
    full: Callable | None
    outer: Callable | None


@functools.cache
def compiled() -> Kernels:
    """The compiled kernels, made at a process's first assembly: importing Numba and loading
    the kernels from its cache take a quarter of a second that a process which never
    assembles a tangent (a learned model answering from cached columns) does not pay.
    """
    return Kernels(make_kernel(), make_full_kernel(), make_outer_kernel())


NUMPY = Kernels(None, None, None)
"""No compiled kernel: the NumPy path everywhere (what the kernels are checked against)."""
