"""Where each entry of each element matrix lands in the tangent's sparse storage.

The tangent is stored in CSR over the free DOFs, its upper triangle only when the linear solver
wants that (PARDISO's Cholesky), both triangles otherwise. The layout is computed once per mesh
and element order: an element matrix's upper entries go straight to their places in the data
(the compiled kernel adds them there), and a potential's node-by-node Hessian (a rigid
object's contact) finds its places by key.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp


@dataclass(eq=False)
class Pattern:
    """The tangent's CSR layout and each element entry's place in it.

    Attributes:
        indices, indptr: the CSR structure (int32), ``nnz`` entries over ``n_free`` rows.
        places: per storage triangle a ``(T, E)`` array: element entry ``e`` of element ``t``
            (its upper entries ``p <= q`` of the ``3n x 3n`` matrix, in ``np.triu_indices``
            order) lands at data index ``places[.][t, e]``, or nowhere (``-1``: a fixed DOF).
        local: ``(A, I, B, K)``: entry ``e`` couples node ``A[e]``'s component ``I[e]`` with
            node ``B[e]``'s component ``K[e]`` (local numbering).
        free: the free DOFs (``3 node + i``) the rows stand for; ``upper``: upper triangle only.
    """

    indices: np.ndarray
    indptr: np.ndarray
    places: list
    local: tuple
    free: np.ndarray
    upper: bool
    _gather: tuple | None = field(default=None, repr=False)
    _keys: np.ndarray | None = field(default=None, repr=False)

    @property
    def nnz(self) -> int:
        return len(self.indices)

    @classmethod
    def of(cls, conn: np.ndarray, n_all: int, free: np.ndarray, upper: bool) -> "Pattern":
        """The layout for elements ``conn`` ``(T, n)`` over ``n_all`` nodes with ``free`` DOFs.

        Works on unique node pairs (``T n^2`` keys, not ``9 T n^2``): each pair's 3 x 3 block
        is numbered once, and SciPy's CSR conversion orders the entries.
        """
        M, tets, n = n_all, conn, conn.shape[1]
        nf = len(free)
        fmap = np.full(3 * M, -1, dtype=np.int64)
        fmap[free] = np.arange(nf)
        ea, eb = np.triu_indices(n)  # element node pairs a <= b: the only ones used
        na, nb = tets[:, ea], tets[:, eb]  # (T, n(n+1)/2)
        lo, hi = np.minimum(na, nb), np.maximum(na, nb)
        pairs, inv = np.unique((lo * M + hi).ravel(), return_inverse=True)
        idx = np.int32 if 18 * len(pairs) < 2**31 else np.int64  # halves the big arrays
        pinv = np.zeros((len(tets), n, n), dtype=idx)
        pinv[:, ea, eb] = inv.reshape(len(tets), -1)
        plo, phi = np.divmod(pairs, M)
        i, k = np.divmod(np.arange(9), 3)
        row = fmap[3 * plo[:, None] + i]  # (P, 9) entry (i, k)
        col = fmap[3 * phi[:, None] + k]
        ok = (row >= 0) & (col >= 0) & ((plo[:, None] < phi[:, None]) | (i <= k))
        ids = np.flatnonzero(ok.ravel())
        r, c = row.ravel()[ids], col.ravel()[ids]
        if upper:
            rr, cc, tag = r, c, ids + 1
        else:  # mirror off-diagonals
            off = r != c
            rr = np.concatenate([r, c[off]])
            cc = np.concatenate([c, r[off]])
            tag = np.concatenate([ids + 1, -(ids[off] + 1)])
        K = sp.csr_matrix((tag.astype(float), (rr, cc)), shape=(nf, nf))
        K.sort_indices()
        tags = K.data.astype(np.int64)
        up = np.full(9 * len(pairs), -1, dtype=idx)
        dn = np.full(9 * len(pairs), -1, dtype=idx)
        up[tags[tags > 0] - 1] = np.flatnonzero(tags > 0)
        dn[-tags[tags < 0] - 1] = np.flatnonzero(tags < 0)
        # element entry (a, i, b, k), p <= q -> pair entry (i, k), or (k, i) if node a > node b
        p, q = np.triu_indices(3 * n)
        A, I, B, Kc = p // 3, p % 3, q // 3, q % 3
        swap = tets[:, A] > tets[:, B]  # (T, E)
        eid = pinv[:, A, B]
        eid *= 9
        eid += np.where(swap, (3 * Kc + I).astype(idx), (3 * I + Kc).astype(idx))
        places = [up[eid]] if upper else [up[eid], dn[eid]]
        return cls(
            K.indices.astype(np.int32),
            K.indptr.astype(np.int32),
            places,
            (A, I, B, Kc),
            np.asarray(free),
            upper,
        )

    @property
    def gather(self) -> tuple:
        """``(places, selections)``: the NumPy path's flat places of the entries that have one."""
        if self._gather is None:
            flat = [pos.ravel() for pos in self.places]
            sel = [np.flatnonzero(pos >= 0) for pos in flat]
            self._gather = ([pos[s] for pos, s in zip(flat, sel)], sel)
        return self._gather

    def entries(self, rows: np.ndarray, cols: np.ndarray, vals: np.ndarray) -> np.ndarray:
        """``(nnz,)``: Hessian entries over DOF indices ``3 node + i`` summed into the data;
        those on fixed DOFs (or below the diagonal, when only the upper triangle is kept)
        dropped. They must lie inside the elements' pattern (a node's own block always does).
        """
        nf = len(self.free)
        index = np.full(int(max(rows.max(initial=0), cols.max(initial=0))) + 1, -1, np.int64)
        inside = self.free[self.free < len(index)]
        index[inside] = np.searchsorted(self.free, inside)
        r, c = index[rows], index[cols]
        keep = (r >= 0) & (c >= 0)
        if self.upper:
            keep &= r <= c
        r, c, vals = r[keep], c[keep], vals[keep]
        if self._keys is None:
            row_of = np.repeat(np.arange(nf, dtype=np.int64), np.diff(self.indptr))
            self._keys = row_of * nf + self.indices
        key = r * nf + c
        at = np.searchsorted(self._keys, key)
        found = at < len(self._keys)
        found[found] = self._keys[at[found]] == key[found]
        if not found.all():
            raise RuntimeError("a potential's Hessian reaches outside the tangent's pattern")
        return np.bincount(at, weights=vals, minlength=self.nnz)
