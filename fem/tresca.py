"""Contact forces within friction disks: the least-energy forces under Tresca's law, lagged
into Coulomb's.

A few skin vertices ``A`` are held by rigid objects: each is to reach its ``target`` ``t_i``
(m; where it would go sticking to the objects' surface), the skin's compliance among them is
``G`` ``(3 a, 3 a)`` (m/N). With each vertex's force ``f_i`` (N) limited to the set

    K_i = { f : p = -f . n_i >= 0,  |f - (f . n_i) n_i| <= b_i }

(a push along the inward normal, and a tangential part within a disk of radius ``b_i``, N:
Tresca's law), the forces minimise the complementary energy

    E(f) = 1/2 f . G f - f . t        over f_i in K_i.

``E`` is strictly convex and each ``K_i`` convex, so the answer is unique and moves
continuously with ``G``, ``t`` and ``b``: its optimality conditions are the contact's
(a vertex pushed lies on the surface, ``(G f)_n = t_n``; one let go lies outside it,
``(G f)_n <= t_n``; one within its disk sticks, ``(G f)_t = t_t``; one on its rim slides
against its force). Coulomb's law takes the disks' radii from the normal forces,
``b_i = mu p_i``: the radii are lagged, taken from the forces of the pass before (the first
from the forces the caller starts from, the last step's), in :data:`PASSES` passes, and the
answer's tangential parts are brought within ``mu p_i`` at the end. The friction of the FEM
lags its pressures in the same way (:mod:`fem.friction`).

Each pass is solved by accelerated projected gradient descent (FISTA with adaptive restart:
Beck and Teboulle 2009, SIAM J. Imaging Sci. 2(1) 183; O'Donoghue and Candes 2015, Found.
Comput. Math. 15 715), its step ``1 / lambda_max(G)``, each iterate projected onto the sets
``K_i`` (a half-line along ``n_i`` times a disk: the projection clamps the push at zero and
scales the tangential part into the disk). On the forearm grips' contacts (up to 50 vertices
as force control closes the whole hand to 10 N, ``G``'s condition number up to some 1400) a
pass takes up to some 550 iterations.
"""

from __future__ import annotations

import numpy as np

from stmpl.failures import PredictionFailed

PASSES = 4
"""Passes of the lagged radii a contact solve makes (on the forearm grips' test split, four
passes leave every vertex's tangential force within 0.01 % of Coulomb's bound before the last
projection, two within 7 %)."""

TOLERANCE = 1e-11
"""The relative change of the forces (to the largest) at which a pass stops."""

ITERATIONS = 20000
"""The most iterations a pass may take before it is refused (a hundred times what the grips
need)."""


SMALL = 48
"""DOFs up to which the compiled pass multiplies by ``G`` in its own loop rather than in BLAS
(whose call costs more than the product of a contact of a few vertices)."""


class NotSettled(PredictionFailed):
    """A contact solve whose forces did not settle within :data:`ITERATIONS`: an answer built
    on them is not given.
    """


def project(f: np.ndarray, n: np.ndarray, bound: np.ndarray) -> np.ndarray:
    """``(a, 3)``: the forces ``f`` ``(a, 3)`` (N) brought into the sets ``K_i`` of the module,
    the push along ``-n`` ``(a, 3)`` clamped at zero, the tangential part within ``bound``
    ``(a,)`` (N, >= 0; ``inf``: no limit).
    """
    fn = (f * n).sum(1)
    ft = f - fn[:, None] * n
    size = np.linalg.norm(ft, axis=1)
    over = size > bound  # with bound >= 0, size > 0 wherever it is over
    scale = np.where(over, bound / np.where(over, size, 1.0), 1.0)
    return np.minimum(fn, 0.0)[:, None] * n + ft * scale[:, None]


def pushes(f: np.ndarray, n: np.ndarray) -> np.ndarray:
    """``(a,)`` N: each force's push ``-f . n`` (>= 0 for a force of the sets ``K_i``, within
    rounding: a vertex let go keeps a tangential part, whose product with a unit normal
    rounds to some 1e-17 of it either way).
    """
    return -(f * n).sum(1)


def radii(f: np.ndarray, n: np.ndarray, friction: float) -> np.ndarray:
    """``(a,)`` N: Coulomb's disk radii ``friction * p_i`` of the forces ``f`` ``(a, 3)``, each
    push ``p_i`` (:func:`pushes`) taken as zero where it rounds below (a radius below zero
    is no disk: the projection onto it would divide by a zero tangential force).
    """
    return friction * np.maximum(pushes(f, n), 0.0)


def within_disks(
    G: np.ndarray, n: np.ndarray, target: np.ndarray, bound: np.ndarray, start, L=None
):
    """``(a, 3)`` N: the least-energy forces of one pass (see the module) on ``a`` vertices with
    compliance ``G`` ``(3 a, 3 a)`` (m/N, vertex by vertex, x y z), outward normals ``n``
    ``(a, 3)``, ``target`` ``(a, 3)`` (m) and disks of radius ``bound`` ``(a,)`` (N), the
    iteration started from ``start`` ``(a, 3)``, its step ``1 / L`` (``L`` m/N: ``G``'s largest
    eigenvalue, found here where ``None``). Refused where it does not settle within
    :data:`ITERATIONS`.
    """
    L = float(np.linalg.eigvalsh(G)[-1]) if L is None else float(L)
    t = target.ravel()
    x = project(start, n, bound)
    y, theta = x.copy(), 1.0
    for _ in range(ITERATIONS):
        step = project(y - (G @ y.ravel() - t).reshape(-1, 3) / L, n, bound)
        theta_next = (1.0 + np.sqrt(1.0 + 4.0 * theta * theta)) / 2.0
        if ((step - x) * (y - step)).sum() > 0:  # the momentum points uphill: restart
            theta_next, y = 1.0, step.copy()
        else:
            y = step + (theta - 1.0) / theta_next * (step - x)
        moved = np.abs(step - x).max()
        x, theta = step, theta_next
        if moved <= TOLERANCE * np.abs(x).max(initial=0.0):
            return x
        if not np.isfinite(moved):
            raise NotSettled("contact: the forces are not finite (the compliance is not definite)")
    raise NotSettled(f"contact: the forces did not settle in {ITERATIONS} iterations")


def coulomb_forces(G, n, target, friction: float, previous) -> np.ndarray:
    """``(a, 3)`` N: the contact forces of the module under Coulomb's ``friction`` (``inf``:
    the skin sticks; ``0``: no friction), the disks' radii lagged over :data:`PASSES` passes
    from the forces ``previous`` ``(a, 3)`` (N; the last step's, zero for a vertex new to the
    contact), and the tangential parts brought within ``friction`` times the push at the end.
    """
    f = np.asarray(previous, dtype=np.float64)
    L = float(np.linalg.eigvalsh(G)[-1])  # the same compliance in every pass
    if not np.isfinite(friction) or friction == 0:
        bound = np.full(len(n), np.inf if friction > 0 else 0.0)
        return within_disks(G, n, target, bound, f, L)
    for _ in range(PASSES):
        f = within_disks(G, n, target, radii(f, n, friction), f, L)
    return project(f, n, radii(f, n, friction))


def _project_loop(compile_):
    """:func:`project` in place, compiled: ``project_into(f, n, bound, out)``."""

    @compile_
    def project_into(f, n, bound, out):  # pragma: no cover - compiled
        for i in range(f.shape[0]):
            fn = f[i, 0] * n[i, 0] + f[i, 1] * n[i, 1] + f[i, 2] * n[i, 2]
            t0 = f[i, 0] - fn * n[i, 0]
            t1 = f[i, 1] - fn * n[i, 1]
            t2 = f[i, 2] - fn * n[i, 2]
            size = np.sqrt(t0 * t0 + t1 * t1 + t2 * t2)
            scale = bound[i] / size if size > bound[i] else 1.0
            push = min(fn, 0.0)
            out[i, 0] = push * n[i, 0] + t0 * scale
            out[i, 1] = push * n[i, 1] + t1 * scale
            out[i, 2] = push * n[i, 2] + t2 * scale

    return project_into


def _disks_loop(compile_, project_into):
    """:func:`within_disks`, compiled and in place: ``disks(G, L, n, t, bound, start)`` with
    ``t`` the target flat ``(3 a,)``.
    """
    tolerance, iterations, small = TOLERANCE, ITERATIONS, SMALL

    @compile_
    def disks(G, L, n, t, bound, start):  # pragma: no cover - compiled
        a = n.shape[0]
        x = np.empty((a, 3))
        project_into(start, n, bound, x)
        y = x.copy()
        z = np.empty((a, 3))  # the gradient step from y, then the projected step
        step = np.empty((a, 3))
        Gy = np.empty(3 * a)
        theta = 1.0
        for _ in range(iterations):
            if 3 * a > small:
                np.dot(G, y.reshape(3 * a), Gy)
            else:  # a few vertices: the product in the loop, no call into BLAS
                for r in range(3 * a):
                    acc = 0.0
                    for c in range(3 * a):
                        acc += G[r, c] * y[c // 3, c % 3]
                    Gy[r] = acc
            for i in range(a):
                for d in range(3):
                    z[i, d] = y[i, d] - (Gy[3 * i + d] - t[3 * i + d]) / L
            project_into(z, n, bound, step)
            theta_next = (1.0 + np.sqrt(1.0 + 4.0 * theta * theta)) / 2.0
            uphill = 0.0
            moved = 0.0
            largest = 0.0
            total = 0.0  # not finite where any force is not
            for i in range(a):
                for d in range(3):
                    uphill += (step[i, d] - x[i, d]) * (y[i, d] - step[i, d])
            momentum = (theta - 1.0) / theta_next
            if uphill > 0:
                theta_next = 1.0
            for i in range(a):
                for d in range(3):
                    s = step[i, d]
                    y[i, d] = s if uphill > 0 else s + momentum * (s - x[i, d])
                    moved = max(moved, abs(s - x[i, d]))
                    x[i, d] = s
                    largest = max(largest, abs(s))
                    total += s
            theta = theta_next
            if not np.isfinite(total):
                raise NotSettled(
                    "contact: the forces are not finite (the compliance is not definite)"
                )
            if moved <= tolerance * largest:
                return x
        raise NotSettled("contact: the forces did not settle in the iterations allowed")

    return disks


def coulomb_loop(compile_):
    """:func:`coulomb_forces`, compiled: ``coulomb(G, n, target, friction, previous)``. The
    same operations in the same order, each iteration in place (no arrays made within it);
    only the product by ``G`` of a contact of up to :data:`SMALL` DOFs is summed in a loop of
    its own, in another order than BLAS's (within 1e-12 of the largest force in the tests).
    """
    passes = PASSES
    project_into = _project_loop(compile_)
    disks = _disks_loop(compile_, project_into)

    @compile_
    def radii_(f, n, friction):  # pragma: no cover - compiled
        b = np.empty(f.shape[0])
        for i in range(f.shape[0]):
            p = -(f[i, 0] * n[i, 0] + f[i, 1] * n[i, 1] + f[i, 2] * n[i, 2])
            b[i] = friction * max(p, 0.0)
        return b

    @compile_
    def coulomb(G, n, target, friction, previous):  # pragma: no cover - compiled
        f = previous.copy()
        t = target.copy().reshape(3 * n.shape[0])
        L = np.linalg.eigvalsh(G)[-1]  # the same compliance in every pass
        if not np.isfinite(friction) or friction == 0:
            bound = np.full(n.shape[0], np.inf if friction > 0 else 0.0)
            return disks(G, L, n, t, bound, f)
        for _ in range(passes):
            f = disks(G, L, n, t, radii_(f, n, friction), f)
        out = np.empty_like(f)
        project_into(f, n, radii_(f, n, friction), out)
        return out

    return coulomb
