"""Compiled steps of :mod:`fem.closure`'s ``"one_at_a_time"`` contact rule."""

from __future__ import annotations

import numpy as np


def past_bound_loop(compile_):
    """The sticking vertex furthest past Coulomb's bound (``"one_at_a_time"``), compiled."""

    @compile_
    def past_bound(f, fn, n, idx, slip, friction):  # pragma: no cover - compiled
        """The sticking vertex (of ``idx``) furthest past Coulomb's bound, its ratio to the
        bound and its tangential force.
        """
        best, m, ft = 0.0, 0, np.zeros(3)
        for q in range(idx.shape[0]):
            i = idx[q]
            if slip[i]:
                continue
            t = np.empty(3)
            for d in range(3):
                t[d] = f[q, d] - fn[q] * n[i, d]
            ratio = np.sqrt(t[0] ** 2 + t[1] ** 2 + t[2] ** 2) / max(friction * -fn[q], 1e-300)
            if ratio > best:
                best, m, ft = ratio, q, t
        return best, m, ft

    return past_bound


def left_inside_loop(compile_):
    """The vertex let go deepest inside the objects (``"one_at_a_time"``), compiled."""

    @compile_
    def left_inside(cols, A, n, target, f, rows, on, back):  # pragma: no cover - compiled
        """The vertex let go (not yet taken back) deepest inside the objects, and its depth
        (m, > 0 inside; -1 and 0 where none is inside).
        """
        deepest, w = 0.0, -1
        for i in range(A.shape[0]):
            if on[i] or back[i]:
                continue
            depth = 0.0
            for d in range(3):
                acc = 0.0
                for q in range(rows.shape[0]):
                    acc += cols[3 * A[i] + d, rows[q]] * f[q // 3, q % 3]
                depth += (acc - target[i, d]) * n[i, d]
            if depth > deepest:
                deepest, w = depth, i
        return deepest, w

    return left_inside
