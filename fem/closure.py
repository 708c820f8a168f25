"""Objects closing on the skin with friction, answered by the skin's linear compliance.

A grip's fingers do not only push the skin in: as they curl they sweep along it, and the skin
they hold goes with them until friction lets it slip. On the layered forearm that drag carries
most of a grip's displacement (held at the FEM's own displacement normal to the skin within
1 cm of the hand, and left free along it, the linear FEM's answer is about as far from the FEM's
as the skin at rest is). This module answers a pose's closure with the linear FEM: the skin's 3D
compliance ``G`` near the objects (:class:`fem.holding.SkinCompliance`), and the objects'
closing replayed over their last stretch of travel in :data:`STEPS` steps.

Each skin vertex ``i`` near the objects has the objects' gap ``g_i`` (m, negative inside) and
their way ``w_i`` (how their surface nearest it moves per metre they close,
:attr:`stmpl.pose.Pose.way`). The FEM presses the objects' surfaces offset outward by their
rounding ``r`` (:data:`fem.shapes.ROUNDING`), so a vertex meets them at ``g_i = r``. Going back
``tau`` (m) along the closing, the gap at rest opens by ``c_i tau`` with ``c_i = -w_i . n_i``
(``n_i`` the skin's outward normal). From the first touch to the pose, step by step, a vertex is
in contact where its gap less its displacement inward is closed, or where it was pushed at the
last step. Each step's target for a vertex in contact is to lie on the objects' surface and
to move along the skin with them (by the objects' sweep along the skin, ``w_i`` less its
normal part, over the part of the step it was in contact), and its contact forces ``f`` (N)
are the least-energy forces within Coulomb's friction disks (:mod:`fem.tresca`, ``mu`` the
friction coefficient): where a vertex's tangential force stays within ``mu`` times its push it
sticks (``G_AA f = u_A`` at the target), on the disk's rim it slides against its force, and
where it would be pulled it is let go, lying outside the objects. Those forces are unique and
move continuously with the pose, so a pose a hair's breadth from another settles as it does
(:data:`CONTACT_RULES` keeps the rule of the models fitted before, which is not so). The skin's
displacement is ``G[:, A] f``. The tissue is linear here and the contact sits at the vertices,
so the answer is a prior, not the FEM: on the forearm grips' test and validation splits it lies
3.4 % and 3.6 % of the peak from the FEM on average (settled by the older rule, as the models
fitted before it are: 4.2 % and 4.0 %; the contact prior alone: 5.1 % and 6.2 %;
``benchmarks/grip_closure.py``). Lengths in m, forces in N.
"""

from __future__ import annotations

import functools

import numpy as np

from fem.friction import SKIN_FRICTION
from fem.shapes import ROUNDING
from fem.tresca import coulomb_forces, coulomb_loop, pushes
from stmpl import jit

STEPS = 20
"""Steps of the replayed closing (on the forearm grips' test split the relative MEE at 10, 20
and 40 steps is 3.66, 3.64 and 3.61 %)."""

MIN_OPENING = 0.05
"""m per m: the least rate at which a vertex's gap opens as the objects go back (``c_i``); an
object point that sweeps along the skin (``w_i`` tangent to it) is taken to open at this."""

CONTACT_RULES = ("least_energy", "all_at_once")
"""How a step's contact settles which vertices stick, slip or are let go (:func:`contact_forces`):

- ``"least_energy"``: the unique least-energy forces within Coulomb's friction disks, their
  radii lagged from the forces before (:mod:`fem.tresca`). A vertex's state follows the forces
  smoothly: the closure of a pose a hair's breadth from another answers as it does, and no
  vertex let go is left inside the objects.
- ``"all_at_once"``: every pulled vertex let go, or every vertex past the bound set slipping
  (its force then along the direction its sticking force pulled), in one pass, a vertex let go
  never taken back within its step; up to :data:`SLIP_PASSES` passes. Under friction two poses
  1e-16 m apart can settle differently (on a forearm grip the squeeze moved by 0.22 N and the
  skin by 0.44 mm, a vertex left 0.09 mm inside a finger): the rule of models fitted before
  ``"least_energy"``, kept for them.
"""

CONTACT_RULE = "least_energy"
"""The rule a closure takes unless told otherwise (a model records its own)."""

SLIP_PASSES = 8
"""Passes of the ``"all_at_once"`` iteration a step makes at most (each pass adds slipping
vertices or lets go of pulled ones; a pass that changes neither ends it)."""


class HeldColumns:
    """The compliance among ``k`` held vertices, ``G[at][:, at]`` ``(3 k, 3 k)`` (m/N, float64),
    read from the skin's whole compliance ``G`` ``(3 N, 3 N)`` column by column as the closure
    first asks for a column (``at`` ``(3 k,)``: the held DOFs, vertex by vertex, x y z; None:
    ``G`` is the held block itself). A grip's contact meets a few of the two hundred vertices
    it holds: on the forearm grips' 96 poses the closure reads 3 % of the block's columns
    (median; at most 8 %), where gathering the whole block (290k entries scattered over the
    skin's 160 MB compliance) takes a third of the closure's time. The answers are the same
    (within 1e-14 of the largest force on those poses).
    """

    def __init__(self, G: np.ndarray, at: np.ndarray | None = None):
        G = np.asarray(G)
        self._G, self._at = G, None if at is None else np.asarray(at, dtype=np.int64)
        m = G.shape[0] if at is None else len(self._at)
        self.shape = (m, m) if at is not None else G.shape
        self._cols = np.empty((m, m)) if at is not None else None
        self._have = np.zeros(m, bool)

    def columns(self, j: np.ndarray) -> np.ndarray:
        """``(3 k, len(j))`` float64: the block's columns ``j`` (its own DOF numbers); refused
        where a column read is not finite.
        """
        j = np.asarray(j, dtype=np.int64)
        if self._at is None:
            return np.asarray(self._G[:, j], dtype=np.float64)
        new = j[~self._have[j]]
        if len(new):
            block = self._G[:, self._at[new]][self._at]
            if not np.isfinite(block).all():
                raise ValueError("closure: G is not finite")
            self._cols[:, new] = block
            self._have[new] = True
        return self._cols[:, j]

    def block(self, j: np.ndarray) -> np.ndarray:
        """``(len(j), len(j))``: the block's rows and columns ``j``."""
        return self.columns(j)[np.asarray(j, dtype=np.int64)]


def closure_forces(
    G,
    normals,
    gap,
    way,
    friction: float = SKIN_FRICTION,
    steps: int = STEPS,
    rounding: float = ROUNDING,
    compiled: bool | None = None,
    rule: str = CONTACT_RULE,
) -> np.ndarray:
    """``(k, 3)`` N: the contact force on each of ``k`` skin vertices as the objects close to
    their pose (see the module). ``G`` ``(3 k, 3 k)`` m/N: the compliance among the vertices
    (vertex by vertex, x y z); ``normals`` ``(k, 3)`` the skin's outward unit normals; ``gap``
    ``(k,)`` m the gap field of the pose; ``way`` ``(k, 3)`` m per m the way field;
    ``friction`` Coulomb's coefficient (``inf``: the skin sticks); ``steps`` of the closing;
    ``rounding`` m the objects' surface offset. The skin's displacement is ``G @ f.ravel()``.
    ``G`` may be a :class:`HeldColumns` (read as the contact reaches its vertices).
    ``compiled``: the steps in the compiled loop (:func:`_kernel`; the same answers within
    rounding, a tenth of the time on a grip or less), where Numba is installed; ``None``: so
    where this process has imported Numba already. Numba's cache does not keep these kernels
    (closures over other compiled functions), so each process compiles them again, some 10 s
    on our machine: one-off answers, as the main job's force control gives, take NumPy's steps
    (0.1-0.2 s a grip) and an application answering many grips loads them once.
    ``rule``: how each step's contact settles (:data:`CONTACT_RULES`).
    """
    if not isinstance(G, HeldColumns):
        G = np.asarray(G, dtype=np.float64)
    n = np.asarray(normals, dtype=np.float64)
    g = np.asarray(gap, dtype=np.float64)
    w = np.asarray(way, dtype=np.float64)
    k = len(g)
    if g.shape != (k,) or n.shape != (k, 3) or w.shape != (k, 3) or G.shape != (3 * k, 3 * k):
        raise ValueError(
            f"closure: gap (k,), normals and way (k, 3), G (3k, 3k) for k = {k}; got "
            f"{g.shape}, {n.shape}, {w.shape}, {G.shape}"
        )
    dense = not isinstance(G, HeldColumns)
    for name, x in (("G", G if dense else 0.0), ("normals", n), ("gap", g), ("way", w)):
        if not np.isfinite(x).all():
            raise ValueError(f"closure: {name} is not finite")
    if not (friction >= 0):
        raise ValueError(f"closure: friction must be >= 0 (or inf), got {friction!r}")
    if isinstance(steps, bool) or not isinstance(steps, (int, np.integer)) or steps < 1:
        raise ValueError(f"closure: steps must be a whole number >= 1, got {steps!r}")
    if not (np.isfinite(rounding) and rounding >= 0):
        raise ValueError(f"closure: rounding must be a length >= 0 m, got {rounding!r}")
    if rule not in CONTACT_RULES:
        raise ValueError(f"closure: rule must be one of {CONTACT_RULES}, got {rule!r}")
    if dense:
        G = HeldColumns(G)
    g = g - rounding
    c = np.maximum(-(w * n).sum(1), MIN_OPENING)
    forces = np.zeros((k, 3))
    travel = max(float((-g / c).max(initial=0.0)), 0.0)  # from the first touch to the pose
    if travel == 0.0:
        return forces
    u = np.zeros((k, 3))
    along = w - (w * n).sum(1, keepdims=True) * n  # the objects' sweep along the skin
    taus = np.linspace(travel, 0.0, steps + 1)
    kernel = _kernel(rule) if (jit.loaded() if compiled is None else compiled) else None
    if kernel is not None:
        big, at = (G._G, G._at) if G._at is not None else (G._G, np.arange(3 * k))
        return kernel(big, at, n, g, c, along, taus, float(friction), SLIP_PASSES)
    for before, tau in zip(taus[:-1], taus[1:]):
        gap_now = g + tau * c - (n * u).sum(1)
        pushed = (forces * n).sum(1) < 0
        A = np.flatnonzero((gap_now <= 0) | pushed)
        if not len(A):
            continue
        # in contact for the whole step, or for the part of it since the objects reached it
        share = np.where(pushed[A], 1.0, np.clip(-gap_now[A] / (c[A] * (before - tau)), 0, 1))
        target = u[A] + share[:, None] * along[A] * (before - tau)
        target += n[A] * (g[A] + tau * c[A] - (n[A] * target).sum(1))[:, None]  # on the surface
        A, f = contact_forces(G, A, n[A], target, friction, rule, forces[A])
        forces = np.zeros((k, 3))
        forces[A] = f
        u = (G.columns(_dofs(A)) @ f.ravel()).reshape(k, 3)  # the load is on A alone
    return forces


def _dofs(A: np.ndarray) -> np.ndarray:
    """``(3 a,)`` the DOFs of vertices ``A`` ``(a,)``, vertex by vertex, x y z."""
    return (np.asarray(A)[:, None] * 3 + np.arange(3)).ravel()


def contact_forces(
    G, A, normals, target, friction: float, rule: str = CONTACT_RULE, previous=None
) -> tuple[np.ndarray, np.ndarray]:
    """``(A', f)``: the vertices of ``A`` ``(a,)`` that stay in contact and their forces
    ``(a', 3)`` (N) for the skin to meet ``target`` ``(a, 3)`` (m) there, as ``rule`` settles
    them (:data:`CONTACT_RULES`) under Coulomb's ``friction`` with ``normals`` ``(a, 3)``;
    the rest of the ``k`` vertices of the compliance ``G`` ``(3 k, 3 k)`` (an array or a
    :class:`HeldColumns`) are free of load. ``previous`` ``(a, 3)`` (N): the forces on ``A``
    before (the last step's; ``None``: none), from which ``"least_energy"`` lags its disks.
    """
    if not isinstance(G, HeldColumns):
        G = HeldColumns(np.asarray(G, dtype=np.float64))
    A, n, target = np.asarray(A), np.asarray(normals), np.asarray(target)
    if rule == "all_at_once":
        return _all_at_once(G, A, n, target, friction)
    if rule != "least_energy":
        raise ValueError(f"closure: rule must be one of {CONTACT_RULES}, got {rule!r}")
    if not len(A):
        return A, np.zeros((0, 3))
    start = np.zeros((len(A), 3)) if previous is None else np.asarray(previous, dtype=np.float64)
    f = coulomb_forces(G.block(_dofs(A)), n, target, friction, start)
    keep = np.flatnonzero(pushes(f, n) > 0)
    return A[keep], f[keep]


def _all_at_once(G, A, n, target, friction) -> tuple[np.ndarray, np.ndarray]:
    """:func:`contact_forces` by the ``"all_at_once"`` rule."""
    slip = np.zeros(len(A), bool) if np.isfinite(friction) else None
    along = np.zeros((len(A), 3))
    for _ in range(SLIP_PASSES):
        f = _solve(G, A, n, target, slip, along, friction)
        fn = (f * n).sum(1)
        pulled = fn > 0
        if pulled.any() and not pulled.all():
            A, n, target, along = A[~pulled], n[~pulled], target[~pulled], along[~pulled]
            slip = None if slip is None else slip[~pulled]
            continue
        if pulled.all():
            return A[:0], np.zeros((0, 3))
        if slip is None:
            return A, f
        ft = f - fn[:, None] * n
        size = np.linalg.norm(ft, axis=1)
        over = ~slip & (size > friction * -fn * (1 + 1e-9))
        if not over.any():
            return A, f
        along[over] = ft[over] / np.maximum(size[over], 1e-300)[:, None]
        slip = slip | over
    return A, f


def _solve(G, A, n, target, slip, along, friction) -> np.ndarray:
    """The forces ``(a, 3)`` with each sticking vertex of ``A`` at ``target`` and each slipping
    one (``slip``) at its normal part, its force ``x (n + friction along)`` (``x < 0``: a
    push, ``along`` its tangential direction).
    """
    a = len(A)
    GAA = G.block(_dofs(A))
    if slip is None or not slip.any():
        return np.linalg.solve(GAA, target.ravel()).reshape(a, 3)
    stick = np.flatnonzero(~slip)
    slipping = np.flatnonzero(slip)
    m = 3 * len(stick) + len(slipping)
    B = np.zeros((3 * a, m))  # force directions, one column per unknown
    C = np.zeros((3 * a, m))  # the displacements each unknown's condition reads
    for j, v in enumerate(stick):
        B[3 * v : 3 * v + 3, 3 * j : 3 * j + 3] = np.eye(3)
    C[:, : 3 * len(stick)] = B[:, : 3 * len(stick)]
    cols = 3 * len(stick) + np.arange(len(slipping))
    for col, v in zip(cols, slipping):
        B[3 * v : 3 * v + 3, col] = n[v] - friction * along[v]
        C[3 * v : 3 * v + 3, col] = n[v]
    x = np.linalg.solve(C.T @ GAA @ B, C.T @ target.ravel())
    return (B @ x).reshape(a, 3)


@functools.lru_cache(maxsize=2)
def _kernel(rule: str = CONTACT_RULE):
    """:func:`closure_forces`'s steps (and :func:`contact_forces`' and :func:`_solve`'s work
    within them) as one compiled loop, or ``None`` without Numba: ``kernel(G, at, n, g, c,
    along, taus, friction, passes)`` with the compliance ``G`` ``(3 N, 3 N)`` whose DOFs ``at``
    are held (its columns read as the contact reaches them), ``g`` the gap less the rounding,
    ``c`` each vertex's opening rate, ``along`` the objects' sweep along the skin and ``taus``
    the closing's steps, all as :func:`closure_forces` makes them, each step's contact settled
    by ``rule``. The same operations in the same order; only the skin's displacement from the
    forces is summed in another order (within some 1e-15 of the forces on the forearm grips).
    """
    compile_ = jit.njit(error_model="numpy")
    if compile_ is None:
        return None
    dofs, read = _dofs_loop(compile_), _read_loop(compile_)
    block = _block_loop(compile_, dofs, read)
    if rule == "least_energy":
        settle = _least_energy_loop(compile_, block)
    else:
        settle = _contact_loop(compile_, _solve_loop(compile_, block), dofs)
    return _closure_loop(compile_, settle, read, dofs)


def _dofs_loop(compile_):
    """The DOFs of vertices ``A``, compiled."""

    @compile_
    def dofs(A):  # pragma: no cover - compiled
        out = np.empty(3 * A.shape[0], np.int64)
        for i in range(A.shape[0]):
            for d in range(3):
                out[3 * i + d] = 3 * A[i] + d
        return out

    return dofs


def _read_loop(compile_):
    """The held block's columns read into ``cols`` as first asked for, compiled: column ``q``
    is row ``q`` of ``cols``, contiguous (a step's few columns are then a few rows, written
    and summed in place, where a column of a C-ordered block touches every row's page).
    """

    @compile_
    def read(G, at, cols, have, rows):  # pragma: no cover - compiled
        for q in rows:
            if not have[q]:
                col = at[q]
                for r in range(at.shape[0]):
                    v = G[at[r], col]
                    if not np.isfinite(v):
                        raise ValueError("closure: G is not finite")
                    cols[q, r] = v
                have[q] = True

    return read


def _block_loop(compile_, dofs, read):
    """The held block's rows and columns of vertices ``A`` (read as first asked for), compiled."""

    @compile_
    def block(G, at, cols, have, A):  # pragma: no cover - compiled
        rows = dofs(A)
        read(G, at, cols, have, rows)
        GAA = np.empty((rows.shape[0], rows.shape[0]))
        for i in range(rows.shape[0]):
            for j in range(rows.shape[0]):
                GAA[i, j] = cols[rows[j], rows[i]]  # row q of cols: the block's column q
        return GAA

    return block


def _solve_loop(compile_, block):
    """:func:`_solve`, compiled."""

    @compile_
    def solve(G, at, cols, have, A, n, target, slip, along, friction):  # pragma: no cover
        a = A.shape[0]
        GAA = block(G, at, cols, have, A)
        t = target.copy().reshape(3 * a)
        if not slip.any():
            return np.linalg.solve(GAA, t).reshape(a, 3)
        stick = np.nonzero(~slip)[0]
        slipping = np.nonzero(slip)[0]
        s3 = 3 * stick.shape[0]
        m = s3 + slipping.shape[0]
        B = np.zeros((3 * a, m))
        C = np.zeros((3 * a, m))
        for j in range(stick.shape[0]):
            v = stick[j]
            for d in range(3):
                B[3 * v + d, 3 * j + d] = 1.0
                C[3 * v + d, 3 * j + d] = 1.0
        for q in range(slipping.shape[0]):
            v = slipping[q]
            for d in range(3):
                B[3 * v + d, s3 + q] = n[v, d] - friction * along[v, d]
                C[3 * v + d, s3 + q] = n[v, d]
        CT = np.ascontiguousarray(C.T)
        x = np.linalg.solve(CT @ GAA @ B, CT @ t)
        return (B @ x).reshape(a, 3)

    return solve


def _least_energy_loop(compile_, block):
    """:func:`contact_forces` by the ``"least_energy"`` rule, compiled (``passes`` unused:
    :data:`fem.tresca.PASSES`).
    """
    coulomb = coulomb_loop(compile_)

    @compile_
    def settle(G, at, cols, have, A, n, target, friction, passes, previous):  # pragma: no cover
        a = A.shape[0]
        GAA = block(G, at, cols, have, A)
        f = coulomb(GAA, n, target, friction, previous)
        keep = np.empty(a, np.bool_)
        for i in range(a):
            keep[i] = -(f[i, 0] * n[i, 0] + f[i, 1] * n[i, 1] + f[i, 2] * n[i, 2]) > 0
        idx = np.nonzero(keep)[0]
        return A[idx], f[idx]

    return settle


def _contact_loop(compile_, solve, dofs):
    """:func:`contact_forces` by the ``"all_at_once"`` rule, compiled."""

    @compile_
    def contact(G, at, cols, have, A, n, target, friction, passes, previous):  # pragma: no cover
        sticks = not np.isfinite(friction)
        slip = np.zeros(A.shape[0], np.bool_)
        along = np.zeros((A.shape[0], 3))
        f = np.zeros((A.shape[0], 3))
        for _ in range(passes):
            f = solve(G, at, cols, have, A, n, target, slip, along, friction)
            a = A.shape[0]
            fn = np.empty(a)
            for i in range(a):
                fn[i] = f[i, 0] * n[i, 0] + f[i, 1] * n[i, 1] + f[i, 2] * n[i, 2]
            pulled = fn > 0
            m = pulled.sum()
            if m > 0 and m < a:
                keep = np.nonzero(~pulled)[0]
                A, n, target, along, slip = A[keep], n[keep], target[keep], along[keep], slip[keep]
                continue
            if m == a:
                return A[:0], np.zeros((0, 3))
            if sticks:
                return A, f
            over = np.zeros(a, np.bool_)
            ft = np.empty((a, 3))
            size = np.empty(a)
            for i in range(a):
                for d in range(3):
                    ft[i, d] = f[i, d] - fn[i] * n[i, d]
                size[i] = np.sqrt(ft[i, 0] * ft[i, 0] + ft[i, 1] * ft[i, 1] + ft[i, 2] * ft[i, 2])
                over[i] = (not slip[i]) and size[i] > friction * -fn[i] * (1 + 1e-9)
            if not over.any():
                return A, f
            for i in range(a):
                if over[i]:
                    for d in range(3):
                        along[i, d] = ft[i, d] / max(size[i], 1e-300)
                    slip[i] = True
        return A, f

    return contact


def _closure_loop(compile_, contact, read, dofs):
    """The closing's steps of :func:`closure_forces`, compiled."""

    @compile_
    def closure(G, at, n, g, c, along, taus, friction, passes):  # pragma: no cover
        k = g.shape[0]
        cols = np.empty((3 * k, 3 * k))
        have = np.zeros(3 * k, np.bool_)
        forces = np.zeros((k, 3))
        u = np.zeros((k, 3))
        gap_now = np.empty(k)
        pushed = np.zeros(k, np.bool_)
        for s in range(taus.shape[0] - 1):
            before, tau = taus[s], taus[s + 1]
            touched = np.empty(k, np.int64)
            a = 0
            for i in range(k):
                gap_now[i] = (
                    g[i] + tau * c[i] - (n[i, 0] * u[i, 0] + n[i, 1] * u[i, 1] + n[i, 2] * u[i, 2])
                )
                push = forces[i, 0] * n[i, 0] + forces[i, 1] * n[i, 1] + forces[i, 2] * n[i, 2]
                pushed[i] = push < 0
                if gap_now[i] <= 0 or pushed[i]:
                    touched[a] = i
                    a += 1
            if a == 0:
                continue
            A = touched[:a].copy()
            nA = np.empty((a, 3))
            target = np.empty((a, 3))
            previous = np.empty((a, 3))  # the forces of the last step, where the disks start
            dt = before - tau
            for q in range(a):
                i = A[q]
                share = 1.0
                if not pushed[i]:
                    share = min(max(-gap_now[i] / (c[i] * dt), 0.0), 1.0)
                for d in range(3):
                    nA[q, d] = n[i, d]
                    previous[q, d] = forces[i, d]
                    target[q, d] = u[i, d] + share * along[i, d] * dt
            for q in range(a):
                i = A[q]
                dot = nA[q, 0] * target[q, 0] + nA[q, 1] * target[q, 1] + nA[q, 2] * target[q, 2]
                gap_q = g[i] + tau * c[i] - dot
                for d in range(3):
                    target[q, d] = target[q, d] + nA[q, d] * gap_q
            A, f = contact(G, at, cols, have, A, nA, target, friction, passes, previous)
            forces[:] = 0.0
            u[:] = 0.0
            rows = dofs(A)
            read(G, at, cols, have, rows)
            for q in range(A.shape[0]):
                for d in range(3):
                    forces[A[q], d] = f[q, d]
            flat = u.reshape(3 * k)  # summed over the forces in their order, as before
            for q in range(rows.shape[0]):
                fq, col = f[q // 3, q % 3], cols[rows[q]]
                for r in range(3 * k):
                    flat[r] += col[r] * fq
        return forces

    return closure
