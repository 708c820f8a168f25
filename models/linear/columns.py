"""The linear FEM's answer from its columns, in NumPy: the thickness interpolated over the
operator's levels, the levels a scene's tissue needs, and the weighted sum of the loaded columns
(from a :class:`fem.compliance.ColumnStore` on demand, or from stored sparse columns). The torch
module (:class:`models.linear.operator.ComplianceOperator`) and the NumPy inference of a GNN
(:mod:`models.gnn.arrays`) answer through these same functions.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp


def interpolation(levels: np.ndarray, t: np.ndarray) -> np.ndarray:
    """``(..., L)`` float32 weights of thicknesses ``t`` ``(...)`` m over ``levels`` ``(L,)``
    (rising): linear between the two levels around each thickness (one level: weight 1).
    """
    L = len(levels)
    w = np.zeros((*np.shape(t), L), np.float32)
    if L == 1:
        w[...] = 1.0
        return w
    t = np.clip(t, levels[0], levels[-1])  # only rounding (checked by grown_levels)
    k = np.clip(np.searchsorted(levels, t), 1, L - 1)
    a = ((t - levels[k - 1]) / (levels[k] - levels[k - 1])).astype(np.float32)
    np.put_along_axis(w, (k - 1)[..., None], (1 - a)[..., None], -1)
    np.put_along_axis(w, k[..., None], a[..., None], -1)
    return w


def grown_levels(
    levels: np.ndarray,
    thickness: np.ndarray,
    on_demand: bool,
    exact: bool = False,
    extend: bool = False,
) -> np.ndarray:
    """The levels ``(L,)`` m (float32) that interpolate ``thickness`` ``(B, N)`` m: on demand,
    with ``exact`` a uniform layer's thickness added as a level and with ``extend`` one beyond
    the levels; otherwise ``ValueError`` for a thickness outside them.
    """
    if len(levels) == 0:
        raise RuntimeError("the compliance operator is empty; fit the predictor first")
    t = np.asarray(thickness, dtype=np.float32)
    lv = np.asarray(levels, dtype=np.float32)
    new = []
    if on_demand and exact and t.size:
        lo_row, hi_row = t.min(-1), t.max(-1)
        uniform = np.unique(lo_row[(hi_row - lo_row) <= 1e-9 * np.maximum(hi_row, 1e-3)])
        new = [x for x in uniform if not (np.abs(lv - x) <= 1e-9).any()]
    lo, hi = float(min([lv[0], *new])), float(max([lv[-1], *new]))
    tmin, tmax = float(t.min()), float(t.max())
    tol = 1e-6 * hi
    beyond = [x for x in (tmin, tmax) if x < lo - tol or x > hi + tol]
    if beyond and not (on_demand and extend):
        raise ValueError(
            f"thickness {tmin * 1e3:.3g}..{tmax * 1e3:.3g} mm lies outside the "
            f"operator's levels {lo * 1e3:g}..{hi * 1e3:g} mm (the linear FEM "
            "was computed there; a linear model with wider levels_mm covers "
            "more)"
        )
    new = sorted(set(new) | set(beyond))
    if new:
        lv = np.sort(np.concatenate([lv, np.asarray(new, np.float32)]))
    return lv


def covers(vertices: int, n: int) -> None:
    """``ValueError`` unless an operator of ``vertices`` vertices answers an input of ``n``."""
    if vertices != n:
        raise ValueError(f"the operator covers {vertices} vertices, the input {n}")


def on_demand_answer(store, levels: np.ndarray, thickness: np.ndarray, force: np.ndarray):
    """``(B, N, 3)`` float32 m: the linear FEM's answer to ``force`` ``(B, N)`` N on tissue
    ``thickness`` ``(B, N)`` m from ``store``'s columns (a :class:`fem.compliance.ColumnStore`)
    at ``levels`` (:func:`grown_levels`): only the loaded vertices' thickness is interpolated,
    and each scene's answer is one weighted sum of its loaded columns per level (the columns of
    the whole batch solved first, one patch per level).
    """
    B, N = force.shape
    covers(store.part.n_vertices, N)
    t = np.asarray(thickness, dtype=np.float32)
    f = np.asarray(force, dtype=np.float32)
    terms: dict[int, list] = {}  # level -> [(scene, columns, weighted forces)]
    for b in range(B):
        cols = np.flatnonzero(f[b])
        if len(cols) == 0:
            continue
        w = interpolation(levels, t[b, cols])  # (K, L)
        for lv in np.flatnonzero(w.any(0)):
            fw = f[b, cols] * w[:, lv]
            keep = fw != 0
            if keep.any():
                terms.setdefault(int(lv), []).append((b, cols[keep], fw[keep]))
    u = np.zeros((B, N, 3), np.float32)
    for lv, rows in terms.items():
        at = store.level(float(levels[lv]))
        store.ensure(at, np.concatenate([c for _, c, _ in rows]))  # one patch
        for b, cols, fw in rows:
            u[b] += store.combination(at, cols, fw)
    return u


def stored_matrices(index: np.ndarray, values: np.ndarray, n: int) -> list:
    """Per level, stored columns as a sparse CSR matrix ``(3 n, n)`` (rows ``3 i + c``) from
    ``index`` ``(2, nnz)`` pairs ``[i; j]`` (response vertex, loaded vertex) and ``values``
    ``(L, nnz, 3)`` m/N.
    """
    i, j = np.asarray(index)
    if i.size and int(max(i.max(), j.max())) >= n:
        covers(int(max(i.max(), j.max())) + 1, n)
    rows = (3 * i[:, None] + np.arange(3)).ravel()
    cols = np.repeat(j, 3)
    return [sp.csr_matrix((v.reshape(-1), (rows, cols)), shape=(3 * n, n)) for v in values]


def stored_answer(matrices: list, levels: np.ndarray, thickness, force) -> np.ndarray:
    """``(B, N, 3)`` float32 m: the stored operator's answer (:func:`stored_matrices`) to
    ``force`` ``(B, N)`` N on tissue ``thickness`` ``(B, N)`` m, the levels interpolated at each
    loaded vertex.
    """
    B, N = force.shape
    fw = np.asarray(force, np.float32)[..., None] * interpolation(levels, thickness)  # (B, N, L)
    u = np.zeros((3 * N, B), np.float32)
    for lv in np.flatnonzero(np.abs(fw).sum((0, 1))):
        u += matrices[lv] @ fw[..., lv].T
    return u.T.reshape(B, N, 3)
