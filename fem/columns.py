"""The product that carries a held answer to the whole skin, ``G[:, at] @ f``, read from the
compliance's columns in place: in float32, or from a copy of them in 16 bits.

A held answer's last step is ``G[:, H] f``: the skin's displacement under forces ``f`` on the
held DOFs ``H``, every row of the compliance ``G`` read for each held column (on the forearm's
grips some 550 columns of 6327 float32 rows, 14 MB, read at memory speed). That product needs
less precision than the compliance keeps: the held block's solve reads ``G`` in float32 (its
condition number is up to some 3e4). Here each column ``j`` is kept as 16-bit integers ``q``
with a scale ``s_j`` (its largest entry over 32767), so that ``G[i, j] = s_j q[i, j]`` within
half a step ``s_j / 2``: half the bytes to read, and the product within ``sum_j |f_j| s_j / 2``
of the float32 one. That bound is small where the forces do not cancel: forces a model answers
on the held skin (:meth:`fem.holding.HeldSkin.push`) moved the answers on the forearm's grips
by at most 4e-6 of their peak. It is not where they do: the forces that hold the skin at a
model's answer (``G[H, H]^-1 r``, :meth:`fem.holding.HeldSkin.answer`) sum to tens of times the
squeeze, and the same product moved those answers by up to 7e-4 of their peak (4.5e-4 with a
scale for every 64 rows of a column), so those keep the float32 columns.

A column is quantised the first time a product reads it and kept; :meth:`Quantized.forget`
drops the columns whose values change (a compliance's column solved after it was read as
zeros). Both products sum their terms in float32 :data:`PRODUCT_RUN` columns at a time and
in float64 across them: a loop of single multiply-adds, which the compiler vectorises (summing
every term in float64 took twice the time, converting each entry).
"""

from __future__ import annotations

import functools

import numpy as np

from stmpl import jit

STEPS = 32767
"""The steps of a column's largest entry in 16 bits (``int16``'s largest value)."""

PRODUCT_RUN = 16
"""Columns a product sums in float32 before adding into float64: the float32 sums' rounding
stays that of a few terms (within 1e-7 of the largest entry in the tests), the float64
additions a sixteenth of the terms."""


def product(G: np.ndarray, at: np.ndarray, f: np.ndarray) -> np.ndarray:
    """``(n,)`` float32: ``G[:, at] @ f`` of ``G`` ``(n, m)`` (float32) on the columns ``at``
    ``(k,)`` and ``f`` ``(k,)``. Where Numba is loaded and ``G`` is kept column by column, the
    columns are read in place in one pass (NumPy gathers them first: 14 MB copied for a grip's
    two hundred held vertices on the forearm, then read again).
    """
    kernel = _kernel() if jit.loaded() and G.flags.f_contiguous else None
    if kernel is None:
        return G[:, at] @ np.asarray(f, dtype=np.float32)
    at = np.asarray(at, dtype=np.int64)
    return kernel(G, _ones(G.shape[1]), at, np.asarray(f, dtype=np.float64))


class Quantized:
    """The columns of ``G`` ``(n, m)`` (float32, kept column by column: Fortran order) in 16
    bits, each with its scale (see the module), made as products ask for them. ``G`` is read,
    never written; the 16-bit copy takes half its memory once every column is read.
    """

    def __init__(self, G: np.ndarray):
        if G.ndim != 2 or G.dtype != np.float32 or not G.flags.f_contiguous:
            raise ValueError(
                f"a quantised compliance is made of a float32 matrix kept column by column, "
                f"got {G.dtype} {G.shape}"
            )
        self.G = G
        self.q = np.zeros(G.shape, np.int16, order="F")
        self.scale = np.zeros(G.shape[1])
        self.have = np.zeros(G.shape[1], bool)

    def forget(self, columns) -> None:
        """Drop ``columns`` ``(k,)`` (made again from ``G`` when next read)."""
        self.have[np.asarray(columns, dtype=np.int64)] = False

    def columns(self, at) -> None:
        """Quantise the columns ``at`` ``(k,)`` not yet kept; refused where one is not finite."""
        at = np.asarray(at, dtype=np.int64)
        new = np.unique(at[~self.have[at]])
        if not len(new):
            return
        block = self.G[:, new]
        if not np.isfinite(block).all():
            raise ValueError("a quantised compliance: G is not finite")
        largest = np.abs(block).max(0).astype(np.float64)
        scale = np.where(largest > 0, largest / STEPS, 1.0)
        self.q[:, new] = np.rint(block / scale).astype(np.int16)
        self.scale[new] = scale
        self.have[new] = True

    def product(self, at, f) -> np.ndarray:
        """``(n,)`` float32: ``G[:, at] @ f`` from the 16-bit columns ``at`` ``(k,)`` and ``f``
        ``(k,)``; compiled where Numba is loaded (each column read in place, its terms summed in
        float32 :data:`PRODUCT_RUN` columns at a time and in float64 across them), NumPy's
        gather otherwise.
        """
        at = np.asarray(at, dtype=np.int64)
        f = np.asarray(f, dtype=np.float64)
        if f.shape != at.shape:
            raise ValueError(f"f must be (k,) = {at.shape} for the columns asked, got {f.shape}")
        self.columns(at)
        kernel = _kernel() if jit.loaded() else None
        if kernel is None:
            return (self.q[:, at] @ (f * self.scale[at])).astype(np.float32)
        return kernel(self.q, self.scale, at, f)


@functools.lru_cache(maxsize=4)
def _ones(m: int) -> np.ndarray:
    """``(m,)`` ones: the scales of a float32 matrix's columns (read-only)."""
    out = np.ones(m)
    out.flags.writeable = False
    return out


@functools.lru_cache(maxsize=1)
def _kernel():
    """The compiled product ``kernel(q, scale, at, f)``, ``G[:, at] @ f`` with ``G[i, j] =
    scale[j] q[i, j]`` (``q`` float32, and ``scale`` ones, or 16-bit steps), or ``None``
    without Numba.
    """
    compile_ = jit.njit(error_model="numpy")
    if compile_ is None:
        return None
    run = PRODUCT_RUN

    @compile_
    def product(q, scale, at, f):  # pragma: no cover - compiled
        n, k = q.shape[0], at.shape[0]
        acc = np.zeros(n)
        part = np.zeros(n, np.float32)
        for j0 in range(0, k, run):
            part[:] = 0.0
            for j in range(j0, min(j0 + run, k)):
                col = at[j]
                w = np.float32(f[j] * scale[col])
                for r in range(n):
                    part[r] += np.float32(q[r, col]) * w
            for r in range(n):
                acc[r] += part[r]
        return acc.astype(np.float32)

    return product
