"""Static equilibrium of the tissue shell: its energy, residual and tangent, solved by Newton's
method (:mod:`fem.newton`).

The displacement ``u`` of the free nodes minimises ``Pi(u) = sum_t V_t W(F_t) - f . u`` with P1
tetrahedra (``F = I + sum_a u_a (x) grad phi_a``, constant per element). Each Newton step solves
``K du = -r`` (``r = dPi/du``, ``K = d^2 Pi/du^2``) and backtracks along ``du`` until the energy
falls (Armijo) with every ``det F > 0``. The inner surface is fixed; more fixed components can be
given. Forces are dead loads (their direction does not follow the skin).

Assembly is a vectorised NumPy kernel over all elements: with the tangent in the form
``A_iJkL = a d_ik d_JL + b H_Ji H_Lk + c H_Li H_Jk`` the element matrix is
``K_aibk = V (a d_ik G_a.G_b + b g_ai g_bk + c g_ak g_bi)`` with ``g_a = H^T G_a``, and the
scatter into the (fixed) sparse pattern is one ``bincount``. A test checks it against
scikit-fem's own assembly.

Nearly incompressible tissue laws (a shape part and a volume part ``U(J)``, bulk modulus ``K``)
take their volume part on each element's mean volume ratio, ``theta_t = (1/V_t) int J dV``
(mean dilatation, Nagtegaal et al. 1974; Simo, Taylor & Pister 1985: the mixed u-p element with
one pressure per element, condensed)::

    Pi(u) = sum_t [ sum_q w_q V_t psi(Ib(F_q) - 3) + V_t U(theta_t) ] - f . u

so the quadratic elements do not lock as ``K / mu`` grows. Its stress adds ``p_t J F^-T`` at
every point (``p_t = U'(theta_t)``, the element's pressure) and its tangent the element's
rank-one matrix ``V_t U''(theta_t) beta beta^T``, ``beta_ai = sum_q w_q J_q (F_q^-T grad N_a)_i``.
The compressible neo-Hookean law (the paper's) keeps its volume term at every point.

Each Newton step solves the current tangent; with a direct linear solver, by conjugate gradients
preconditioned with a kept factorisation (:mod:`fem.tangent`).

A solve that does not converge, or would need an inverted element, returns a :class:`Solution`
with ``ok = False`` and a reason, never a displacement. So does a converged state that pushes the
skin through the fixed inner surface (``inward displacement > thickness``: converged but
non-physical).
"""

from __future__ import annotations

import time
from functools import cached_property

import numpy as np
import scipy.sparse as sp

from fem.elements import ELEMENTS, quadratic
from fem.finer import FinerPart
from fem.kernel import compiled, element_data, outer_data
from fem.kinematics import deformation_gradient, det3, inv3
from fem.linear_solvers import make_linear_solver
from fem.material import NeoHookean
from fem.mesh import ShellMesh
from fem.newton import newton
from fem.options import SolverOptions
from fem.pattern import Pattern
from fem.solution import Solution
from fem.tangent import Tangent
from fem.volume import volume_split, volumetric
from stmpl.part import BodyPart


class Solver:
    """Newton solver for one shell mesh and material; reuse it for many loads (the sparse pattern,
    shape gradients and the linear solver's symbolic analysis are kept).

    Args:
        mesh: the tissue shell (P1 tetrahedra; ``order=2`` adds a node on every edge).
        material: a material with ``energy`` and ``tangent_parts`` (default Neo-Hookean,
            E = 1 kPa, nu = 0.4).
        fixed: optional ``(M, 3)`` bool mask of further fixed components on the mesh nodes (an
            edge node is fixed where both ends are).
        hold_inner: hold the inner surface (bone) in place, all three components (default);
            ``False`` leaves it to ``fixed`` (a slab sliding on a rigid base, say).
        options: :class:`SolverOptions`.
        order: element order, 1 (4-node) or 2 (10-node tetrahedra, four quadrature points).
        answer_on: the part a pressed object's answers (:mod:`fem.contact`) are given on:
            default the mesh's; or a part subdivided from it whose vertices are all skin nodes
            (:class:`fem.finer.FinerPart`, :func:`fem.finer.meshed`).
    """

    def __init__(
        self,
        mesh: ShellMesh,
        material=None,
        fixed: np.ndarray | None = None,
        options: SolverOptions | None = None,
        order: int = 1,
        hold_inner: bool = True,
        answer_on: BodyPart | None = None,
    ):
        if order not in ELEMENTS:
            raise ValueError(f"element order must be 1 or 2, got {order!r}")
        self.mesh = mesh
        self.material = material if material is not None else NeoHookean()
        self.options = options or SolverOptions()
        self.element = ELEMENTS[order]
        M = mesh.n_nodes
        mask = np.zeros((M, 3), dtype=bool)
        mask[mesh.inner_nodes] = hold_inner
        if self.options.rims == "fixed":
            mask[mesh.rim_nodes] = True
        if fixed is not None:
            fixed = np.asarray(fixed, dtype=bool)
            if fixed.shape != (M, 3):
                raise ValueError(f"fixed must have shape ({M}, 3), got {fixed.shape}")
            mask |= fixed
        X = mesh.nodes[mesh.tets]  # (T, 4, 3)
        Dm = (X[:, 1:] - X[:, :1]).transpose(0, 2, 1)  # columns are edges
        Dinv = np.linalg.inv(Dm)
        G1 = np.concatenate([-Dinv.sum(1, keepdims=True), Dinv], 1)  # (T, 4, 3) grad L_k
        self.V = mesh.volumes
        if np.any(self.V <= 0):
            raise ValueError("mesh has inverted or flat elements; check its quality()")
        if order == 1:
            self.conn, self.edges = mesh.tets, np.zeros((0, 2), dtype=np.int64)
        else:
            self.conn, self.edges = quadratic(mesh.tets, M)
            mask = np.concatenate([mask, mask[self.edges[:, 0]] & mask[self.edges[:, 1]]])
        self.n_all = M + len(self.edges)
        self.fixed = mask
        self.free = np.flatnonzero(~mask.ravel())
        el = self.element
        self.G = np.einsum("qak,tkj->tqaj", el.dN, G1)  # (T, Q, n, 3) grad N_a
        self.W = self.V[:, None] * el.weights[None]  # (T, Q) weights, m^3
        self.GG = np.matmul(self.G, self.G.transpose(0, 1, 3, 2))  # (T, Q, n, n)
        self.GW = self.G * self.W[:, :, None, None]  # weighted gradients
        self._force_idx = (3 * self.conn[:, :, None] + np.arange(3)).ravel()
        self.bulk = self.point_bulk = None
        """``(T,)`` each element's bulk modulus (Pa) taken on its mean volume ratio, and on
        its points (0 where the other applies); ``None`` where the law has no bulk modulus or
        the options ask for the volume at every point."""
        if self.options.volume != "point":
            split = volume_split(self.material, len(mesh.tets), self.options.volume)
            self.bulk, self.point_bulk = split or (None, None)
        self.linear = make_linear_solver(self.options.linear_solver)
        self.pattern = Pattern.of(self.conn, self.n_all, self.free, upper=self.linear.upper)
        self.tangent = Tangent(self.linear, self.assemble, self.bulk is not None)
        self.answer_on = answer_on if answer_on is not None else mesh.part
        """The tangent's factorisation Newton's steps keep."""
        self.potentials: list = []
        """Further energies on the nodes (a rigid object's contact, :mod:`fem.contact`), each
        with ``energy(u)``, ``gradient(u)`` and ``hessian(u, upper)``."""

    @property
    def order(self) -> int:
        return self.element.order

    # ------------------------------------------------------------------ assembly
    def deformation_gradient(self, u: np.ndarray) -> np.ndarray:
        """``(T, Q, 3, 3)`` ``F = I + sum_a u_a (x) grad N_a`` at the quadrature points, for
        nodal displacement ``u`` ``(n_all, 3)``.
        """
        return deformation_gradient(u, self.conn, self.G)

    def _F(self, u: np.ndarray) -> np.ndarray:
        return self.deformation_gradient(u).reshape(-1, 3, 3)

    def energy(self, u: np.ndarray, f: np.ndarray) -> float:
        """Total potential energy, J (``inf`` if an element inverts)."""
        F = self._F(u)
        extra = sum(p.energy(u) for p in self.potentials)
        if self.bulk is None:
            stored = self.W.ravel() @ self.material.energy(F)
        else:
            T, Q = self.W.shape
            J = det3(F).reshape(T, Q)
            shape = self.material.shape_energy(F)
            at_points = volumetric(np.repeat(self.point_bulk, Q), J.ravel())[0]
            mean = volumetric(self.bulk, J @ self.element.weights)[0]
            stored = self.W.ravel() @ (shape + at_points) + self.V @ mean
        return float(stored - np.vdot(f, u) + extra)

    def _pressure(self, F: np.ndarray):
        """The volume terms' data at ``F`` ``(T Q, 3, 3)``: ``(F^-T (T Q, 3, 3), J (T, Q),
        U'(theta) (T,), U''(theta) (T,), U'(J) (T Q,), U''(J) (T Q,))``, the mean volume
        ratio's (``bulk``) and the points' own (``point_bulk``).
        """
        T, Q = self.W.shape
        Finv, J = inv3(F)
        _, dUp, d2Up = volumetric(np.repeat(self.point_bulk, Q), J)
        J = J.reshape(T, Q)
        _, dU, d2U = volumetric(self.bulk, J @ self.element.weights)
        return Finv.transpose(0, 2, 1), J, dU, d2U, dUp, d2Up

    def _stress(self, F: np.ndarray) -> np.ndarray:
        """``(T Q, 3, 3)`` first Piola-Kirchhoff stress, Pa (mean dilatation's pressure in)."""
        if self.bulk is None:
            return self.material.stress(F)
        FinvT, J, dU, _, dUp, _ = self._pressure(F)
        pJ = (dU[:, None] * J).reshape(-1) + dUp * J.reshape(-1)
        return self.material.shape_parts(F)[0] + pJ[:, None, None] * FinvT

    def residual(self, u: np.ndarray, f: np.ndarray) -> np.ndarray:
        """``(n_all, 3)`` out-of-balance force ``dPi/du``, N (fixed nodes included)."""
        r = self._scatter_force(self._stress(self._F(u))) - f
        for p in self.potentials:
            r += p.gradient(u)
        return r

    def _scatter_force(self, P: np.ndarray) -> np.ndarray:
        """``(n_all, 3)`` internal nodal forces ``f_a = sum_q w V P grad N_a`` from stresses
        ``(T Q, 3, 3)``.
        """
        T, Q = self.W.shape
        P = P.reshape(T, Q, 3, 3)
        fe = np.matmul(self.GW, P.transpose(0, 1, 3, 2)).sum(1)  # (T, n, 3)
        return np.bincount(self._force_idx, weights=fe.ravel(), minlength=3 * self.n_all).reshape(
            -1, 3
        )

    def assemble(self, u: np.ndarray, f: np.ndarray, definite: bool = False):
        """``(r (n_all, 3), K)``: residual and the tangent on free DOFs (CSR; upper triangle only
        when the linear solver wants it). ``definite``: under mean dilatation, the elements'
        pressure stiffness ``p J ((tr A)^2 - tr(A A))`` (``A = dF F^-1``) is replaced by its
        positive part at every point, ``|p| J |dev sym A|^2`` under compression and
        ``p J (2/3 (tr A)^2 + |skew A|^2)`` under tension: where pressures far above the shear
        modulus make the full tangent indefinite, Newton's steps still descend, and the answer
        is checked against the full tangent.
        """
        T, Q = self.W.shape
        F = self._F(u)
        if self.bulk is None:
            P, parts = self.material.tangent_parts(F)
        else:  # the shape part at the points, the pressure p_t J F^-T of each element
            P, parts = self.material.shape_parts(F)
            FinvT, J, dU, d2U, dUp, d2Up = self._pressure(F)
            pJ = (dU[:, None] * J).reshape(-1)  # the elements' mean pressure, at each point
            Jq = J.reshape(-1)
            P = P + (pJ + dUp * Jq)[:, None, None] * FinvT
            if definite:  # b (tr A)^2 + c tr(A A) + s tr(A A^T), positive semi-definite
                m, push = np.abs(pJ), pJ < 0
                db, dc = np.where(push, -m / 3, 2 * m / 3), np.where(push, m / 2, -m / 2)
            else:
                db, dc = pJ, -pJ
            db, dc = db + Jq * dUp + Jq**2 * d2Up, dc - Jq * dUp  # the points' own volume
            parts = (parts[0], parts[1] + db, parts[2] + dc, *parts[3:])
        a, b, c, H = parts[:4]
        r = self._scatter_force(P)
        g = np.matmul(self.G, np.asarray(H).reshape(T, Q, 3, 3))  # (T, Q, n, 3) H^T grad N
        aW, bW, cW = (np.asarray(x).reshape(T, Q) * self.W for x in (a, b, c))
        GG = self.GG
        if self.bulk is not None and definite:  # tr(A A^T) = d_ik g_a.g_b: into the a term
            s = (0.5 * np.abs(pJ)).reshape(T, Q)
            GG = aW[..., None, None] * self.GG + (s * self.W)[..., None, None] * np.matmul(
                g, g.transpose(0, 1, 3, 2)
            )
            aW = np.ones((T, Q))
        full = None
        if len(parts) == 7:  # a law of I1 and J: the long form
            Fq = np.asarray(parts[6]).reshape(T, Q, 3, 3)
            fg = np.ascontiguousarray(np.matmul(self.G, Fq.transpose(0, 1, 3, 2)))  # F grad N
            full = (fg, *(np.asarray(x).reshape(T, Q) * self.W for x in parts[4:6]))
        volume = None
        if self.bulk is not None:  # each element's rank-one volume term V U'' beta beta^T
            beta = np.einsum("q,tq,tqai->tai", self.element.weights, J, g).reshape(T, -1)
            volume = (beta, self.V * d2U)
        kernel = compiled()
        if kernel is not None:
            data = np.zeros(self.pattern.nnz)
            for pos in self.pattern.places:
                kernel(g, GG, aW, bW, cW, pos, data, full, volume)
        else:
            pat = self.pattern
            data = element_data(g, GG, aW, bW, cW, pat.local, *pat.gather, pat.nnz, full=full)
            if volume is not None:
                data += outer_data(*volume, *pat.gather, pat.local, pat.nnz)
        for p in self.potentials:
            r += p.gradient(u)
            data += self.pattern.entries(*p.hessian(u))
        nf = len(self.free)
        K = sp.csr_matrix((data, self.pattern.indices, self.pattern.indptr), shape=(nf, nf))
        return r - f, K

    def tangent_full(self, u: np.ndarray) -> sp.csr_matrix:
        """The full symmetric tangent on free DOFs (for checks)."""
        _, K = self.assemble(u, np.zeros_like(u))
        if self.linear.upper:
            K = (K + sp.triu(K, 1).T).tocsr()
        return K

    def external_forces(self, force: np.ndarray) -> np.ndarray:
        """``(n_all, 3)`` consistent nodal forces for per-vertex normal forces ``(N,)`` (N)."""
        mesh = self.mesh
        if self.order == 1 or self.options.force_mode == "nodal":
            f = mesh.nodal_forces(force, self.options.force_mode)
            return np.concatenate([f, np.zeros((len(self.edges), 3))])
        n = mesh.part.n_vertices
        force = np.asarray(force, dtype=float)
        if force.shape != (n,):
            raise ValueError(f"force must have shape ({n},), got {force.shape}")
        return (self.force_operator @ force).reshape(-1, 3)

    @cached_property
    def force_operator(self) -> sp.csr_matrix:
        """``(3 n_all, N)``: quadratic elements' :meth:`external_forces` as a sparse map."""
        return self.mesh.quadratic_force_operator(self.edges)

    # ------------------------------------------------------------------ solving
    def solve(self, force: np.ndarray, u0: np.ndarray | None = None) -> Solution:
        """Equilibrium under per-vertex normal ``force`` ``(N,)`` (N) on the part.

        ``u0``: ``(n_all, 3)`` start, the ``state`` of a converged neighbouring solve; else rest.
        A failed increment is retried in up to ``max_substeps`` halvings before the solve fails.
        """
        force = self._check_force(force)
        t0 = time.perf_counter()
        u = np.zeros((self.n_all, 3)) if u0 is None else np.array(u0, dtype=float)
        if u.shape != (self.n_all, 3):
            raise ValueError(
                f"u0 must have shape ({self.n_all}, 3) (a Solution's state), got {u.shape}"
            )
        f_target = self.external_forces(force)
        f_start = self._balanced_force(u) if u0 is not None else np.zeros_like(f_target)
        # march from the start state's load to the target, halving the step on failure
        s, step, iters, substeps, last = 0.0, 1.0, 0, 0, None
        while s < 1.0:
            step = min(step, 1.0 - s)
            f = f_start + (s + step) * (f_target - f_start)
            res = newton(self, u, f)
            iters += res["iterations"]
            last = res
            if res["ok"]:
                u, s = res["u"], s + step
                continue
            if substeps >= self.options.max_substeps:
                return self._fail(res, iters, t0, force, substeps)
            substeps += 1
            step /= 2
        return self._checked_solution(last, u, iters, t0, force, substeps)

    def continuation(self, force: np.ndarray, totals) -> list[Solution]:
        """Solve the load pattern ``force`` ``(N,)`` scaled to each total in ``totals`` (N, rising),
        each level warm-started from the last converged one. After a failure the remaining levels
        are reported as failed without being tried (a higher force cannot be carried either).
        """
        force = self._check_force(force)
        base = force.sum()
        if base <= 0:
            raise ValueError("the load pattern carries no force")
        out, u, failed = [], None, None
        for total in totals:
            if failed is not None:
                out.append(
                    Solution.failed(f"skipped: a lower force ({failed:.3g} N) failed", float(total))
                )
                continue
            sol = self.solve(force * (total / base), u0=u)
            out.append(sol)
            if sol.ok:
                u = sol.state
            else:
                failed = float(total)
        return out

    @cached_property
    def positions(self) -> np.ndarray:
        """``(n_all, 3)`` every node's rest position, m (a quadratic element's edge nodes at
        their edges' midpoints).
        """
        nodes = self.mesh.nodes
        return np.concatenate([nodes, nodes[self.edges].mean(axis=1)])

    @cached_property
    def answers(self) -> FinerPart:
        """How a contact answer reads on the vertices of :attr:`answer_on`."""
        return FinerPart(self, self.answer_on)

    def _check_force(self, force) -> np.ndarray:
        force = np.asarray(force, dtype=float)
        n = self.mesh.part.n_vertices
        if force.shape != (n,):
            raise ValueError(f"force must have shape ({n},), got {force.shape}")
        if not np.all(np.isfinite(force)) or force.min() < 0:
            raise ValueError("force must be finite and >= 0 N at every vertex")
        return force

    def _balanced_force(self, u: np.ndarray) -> np.ndarray:
        """The external force that holds state ``u`` in equilibrium (free DOFs)."""
        r = self.residual(u, np.zeros_like(u)).reshape(-1)
        out = np.zeros_like(r)
        out[self.free] = r[self.free]
        return out.reshape(-1, 3)

    def equilibrium(
        self,
        u: np.ndarray,
        f: np.ndarray,
        rtol: float | None = None,
        floor: float = 0.0,
        check: bool = True,
        definite: bool = False,
    ) -> dict:
        """Newton's method from ``u`` ``(n_all, 3)`` under nodal forces ``f`` ``(n_all, 3)``
        and the :attr:`potentials`, to a relative residual ``rtol`` (default the options'):
        ``{"ok", "u", "iterations", "residual"}`` or, failed, ``{"ok": False, "reason", ...}``.
        ``floor``: a residual at which a step the line search cannot improve ends the solve
        as converged (the round-off floor of a contact whose nodes come and go; 0: never).
        ``check`` and ``definite``: whether the answer's stability is checked, and whether
        solves on the way to it stepped without the pressure stiffness (:func:`fem.newton.newton`).
        """
        return newton(self, np.array(u, dtype=float), f, rtol, floor, check, definite)

    def _fail(self, res, iters, t0, force, substeps) -> Solution:
        return Solution.failed(
            res["reason"],
            float(force.sum()),
            iters,
            res["residual"],
            time=time.perf_counter() - t0,
            substeps=substeps,
        )

    def measures(self, u: np.ndarray) -> tuple[float, float]:
        """``(min det F, compression)`` of state ``u`` ``(n_all, 3)``: the smallest volume
        ratio (over the quadrature points, or of the elements under mean dilatation), and how
        far the skin moves inward as a share of the tissue's depth under it (the largest over
        the skin).
        """
        J = det3(self._F(u)).reshape(self.W.shape)
        if self.bulk is not None:  # an element under mean dilatation: its mean volume ratio
            mean = (self.bulk > 0)[:, None]
            J = np.where(mean, (J @ self.element.weights)[:, None], J)
        detF = float(J.min())
        m = self.mesh
        inward = -np.einsum("si,si->s", u[: m.n_skin], m.skin_normals) / m.thickness
        return detF, float(inward.max())

    def check(self, u: np.ndarray) -> str:
        """Why state ``u`` ``(n_all, 3)`` cannot be trusted, or ``""``: see :meth:`distrust`."""
        return self.distrust(*self.measures(u))

    def distrust(self, detF: float, compression: float) -> str:
        """Why a state of smallest volume ratio ``detF`` and skin ``compression`` (share of
        the depth) cannot be trusted, or ``""``: an inverted element, the skin pushed past
        ``options.max_compression``, or past the material's :class:`~fem.limits.Limits`.
        """
        if detF <= 0:
            return f"inverted element (min det F {detF:.3g})"
        if compression > self.options.max_compression:
            return (
                f"non-physical: the skin moves inward {compression:.2f} x the "
                f"thickness (limit {self.options.max_compression})"
            )
        limits = self.material.limits
        return "" if limits is None else limits.reason(detF, compression)

    def _checked_solution(self, res, u, iters, t0, force, substeps) -> Solution:
        detF, comp = self.measures(u)
        skin_u = u[: self.mesh.n_skin]
        umax = float(np.linalg.norm(skin_u, axis=1).max())
        elapsed = time.perf_counter() - t0
        base = dict(
            iterations=iters,
            residual=res["residual"],
            min_det_F=detF,
            time=elapsed,
            total_force=float(force.sum()),
            substeps=substeps,
            max_displacement=umax,
            max_compression=comp,
        )
        reason = self.distrust(detF, comp)
        if reason:
            return Solution(False, reason, None, **base)
        return Solution(True, "", u[: self.mesh.n_nodes], state=u, **base)
