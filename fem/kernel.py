"""The tangent's element matrices summed into its CSR data, two ways: a compiled kernel (Numba:
each element's matrix summed over its quadrature points in 3 x 3 blocks, then added into the
data with the mean-dilatation volume term in one pass) and its NumPy twin, used without Numba
and to check the kernel.
"""

from __future__ import annotations

import functools
from collections.abc import Callable

import numpy as np

from stmpl.jit import njit


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
    """A Numba kernel adding every element matrix's upper entries to the CSR data:
    ``kernel(g, GG, aW, bW, cW, pos, data, full=None, volume=None)`` with the arguments of
    :func:`element_data` and, for mean dilatation, ``volume = (beta, coef)`` of
    :func:`outer_data`; ``None`` when Numba is absent.
    """
    both = _element_kernel()
    if both is None:
        return None

    def kernel(g, GG, aW, bW, cW, pos, data, full=None, volume=None):
        f, dW, eW = (g, aW, aW) if full is None else full  # f, dW, eW unread when short
        if volume is None:  # beta, coef unread
            beta, coef = np.zeros((len(g), 1)), np.zeros(len(g))
        else:
            beta, coef = np.ascontiguousarray(volume[0]), np.ascontiguousarray(volume[1])
        long, outer = full is not None, volume is not None
        both(g, f, GG, aW, bW, cW, dW, eW, long, beta, coef, outer, pos, data)

    return kernel


@functools.cache
def _element_kernel():
    """The compiled kernel behind :func:`make_kernel`; ``None`` when Numba is absent.

    Each element's matrix is summed over its quadrature points as 3 x 3 blocks ``(a, b)``,
    ``b >= a``: with ``u_b = bW g_b + eW f_b`` and ``v_b = eW g_b + dW f_b`` (made once a
    point), the block is ``g_a u_b^T + f_a v_b^T + cW g_b g_a^T + aW G_ab I``, a third of the
    multiplications of the entries written out, and no division in the loops. The volume
    term ``coef beta beta^T`` is added as the entries go into the data, in the same pass.
    """
    jit = njit()
    if jit is None:
        return None

    @jit
    def kernel(
        g, f, GG, aW, bW, cW, dW, eW, long, beta, coef, outer, pos, data
    ):  # pragma: no cover - compiled
        T, Q, n = g.shape[0], g.shape[1], g.shape[2]
        m = 3 * n
        ke = np.zeros((m, m))  # one element's matrix (upper blocks), summed over its points
        u, v = np.zeros((n, 3)), np.zeros((n, 3))
        for t in range(T):
            ke[:] = 0.0
            for qp in range(Q):
                a, b, c, d, h = aW[t, qp], bW[t, qp], cW[t, qp], dW[t, qp], eW[t, qp]
                gt, ft, Gt = g[t, qp], f[t, qp], GG[t, qp]
                for B in range(n):
                    for k in range(3):
                        u[B, k] = b * gt[B, k] + (h * ft[B, k] if long else 0.0)
                        v[B, k] = h * gt[B, k] + d * ft[B, k] if long else 0.0
                for A in range(n):
                    for B in range(A, n):
                        for i in range(3):
                            gai, cgbi = gt[A, i], c * gt[B, i]
                            fai = ft[A, i] if long else 0.0
                            for k in range(3):
                                ke[3 * A + i, 3 * B + k] += (
                                    gai * u[B, k] + fai * v[B, k] + cgbi * gt[A, k]
                                )
                            ke[3 * A + i, 3 * B + i] += a * Gt[A, B]
            e = 0
            for p in range(m):
                bp = coef[t] * beta[t, p] if outer else 0.0
                for q in range(p, m):
                    j = pos[t, e]
                    e += 1
                    if j >= 0:
                        data[j] += ke[p, q] + (bp * beta[t, q] if outer else 0.0)

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


@functools.cache
def compiled() -> Callable | None:
    """The compiled kernel (:func:`make_kernel`), made at a process's first assembly:
    importing Numba and loading the kernel from its cache take a quarter of a second that a
    process which never assembles a tangent (a learned model answering from cached columns)
    does not pay. ``None`` without Numba: the NumPy path instead.
    """
    return make_kernel()
