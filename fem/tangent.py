"""The tangent's factorisation that Newton's steps keep, and the steps solved with it.

Each Newton step solves the current tangent ``K du = -r``. With a direct linear solver the last
factorisation is kept, from step to step and from solve to solve, as the preconditioner of
conjugate gradients on the current tangent (a back-substitution costs a thirtieth of a
factorisation on the reference arm), and the tangent is factorised afresh only where that no
longer converges within a few iterations. Under mean dilatation a tangent that is not positive
definite is factorised without its pressure stiffness (``definite``, see
:meth:`fem.solver.Solver.assemble`); CG is not tried on that one, which changes too much from
step to step for an earlier one to precondition it.
"""

from __future__ import annotations

import inspect
import weakref
from collections.abc import Callable

import numpy as np

from fem.krylov import pcg, symmetric_matvec
from fem.linear_solvers import IndefiniteTangent

KRYLOV_RTOL = 1e-3
"""A Newton step solved by preconditioned CG leaves this share of the residual's linear part
(an inexact Newton method: the residual still falls a thousandfold per step near an answer)."""

KRYLOV_ITERATIONS = (10, 20)
"""Preconditioned CG iterations after which the tangent is factorised afresh for the next step,
and at which a step gives up on CG and factorises now (a factorisation of the reference arm
costs some thirty back-substitutions and a tangent's assembly)."""


class Tangent:
    """A solver's linear solver and what its factorisation holds.

    Args:
        linear: a linear solver (:mod:`fem.linear_solvers`).
        assemble: ``(u, f, definite) -> (r, K)``, the solver's :meth:`~fem.solver.Solver.assemble`
            (kept as a weak method: a solver that holds its tangent is no reference cycle, so
            its factorisation, PARDISO's memory outside Python, goes with the solver at once).
        can_leave_out: whether the tangent has a pressure stiffness to leave out (mean
            dilatation).
    """

    def __init__(self, linear, assemble: Callable, can_leave_out: bool):
        self.linear = linear
        self._assemble = weakref.WeakMethod(assemble) if inspect.ismethod(assemble) else assemble
        self.can_leave_out = can_leave_out
        self.factored: str | None = None
        """``"full"`` (the tangent), ``"definite"`` (less its pressure stiffness) or ``None``."""

    def assemble(self, u: np.ndarray, f: np.ndarray, definite: bool):
        """The solver's assembly ``(r, K)`` at ``u``."""
        assemble = self._assemble
        if isinstance(assemble, weakref.WeakMethod):
            assemble = assemble()
        return assemble(u, f, definite)

    def factorise(
        self, u: np.ndarray, f: np.ndarray, definite: bool = False, K=None, confirm: bool = True
    ) -> tuple[str, int] | None:
        """Assemble and factorise the tangent at ``u``; ``None``, or why it failed and whether
        the iteration counts (``(reason, 1)`` when the tangent itself was built).
        ``definite``: the tangent without the pressure stiffness; ``K``: the full tangent at
        ``u`` where it is at hand; ``confirm``: as the linear solver's ``factor`` (``False``:
        a single-precision factorisation's non-positive pivot is not checked in double).
        """
        self.factored = None
        try:
            if K is None or definite:
                _, K = self.assemble(u, f, definite)
            self.linear.factor(K, confirm)
        except IndefiniteTangent:
            return "indefinite tangent: the layer buckles", 1
        except (RuntimeError, ValueError) as e:
            return f"linear solve failed: {e}", 0
        self.factored = "definite" if definite else "full"
        return None

    def refactorise(self, u: np.ndarray, f: np.ndarray, K=None) -> tuple[str, int] | None:
        """:meth:`factorise` at ``u`` (``K``: the full tangent there, where at hand); an
        indefinite tangent is tried again without its pressure stiffness where it has one
        (:attr:`factored` then says ``"definite"``): a step's tangent, so a single-precision
        factorisation's word that it is indefinite is taken there without a double one (an
        answer reached with such steps is checked against the full tangent, confirmed).
        """
        failed = self.factorise(u, f, K=K, confirm=not self.can_leave_out)
        if failed is not None and failed[1] and self.can_leave_out:
            return self.factorise(u, f, definite=True)
        return failed

    def krylov(self, K, rhs: np.ndarray) -> tuple[np.ndarray | None, int]:
        """``(x (n, k) or None, the most CG iterations a column took)``: conjugate gradients on
        ``K`` for each column of ``rhs`` ``(n, k)``, preconditioned by the kept factorisation
        (``None`` where one does not converge within :data:`KRYLOV_ITERATIONS`).
        """
        matvec, out, most = symmetric_matvec(K, self.linear.upper), [], 0
        for b in rhs.T:
            try:
                got = pcg(matvec, self.linear.precondition, b, KRYLOV_RTOL, KRYLOV_ITERATIONS[1])
            except (RuntimeError, ValueError):
                return None, KRYLOV_ITERATIONS[1]
            if got.x is None:
                return None, KRYLOV_ITERATIONS[1]
            out.append(got.x)
            most = max(most, got.iterations)
        return np.stack(out, axis=1), most

    def direction(self, u: np.ndarray, f: np.ndarray, rf: np.ndarray, refresh: bool, cg: bool):
        """Newton's step at ``u`` for the free residual ``rf``: :meth:`steps` for ``-rf``.
        Returns ``(du, failure or None, whether the tangent was factorised, whether CG was
        slow)``.
        """
        x, failure, fresh, slow = self.steps(u, f, -rf[:, None], refresh, cg)
        return (None if x is None else x[:, 0]), failure, fresh, slow

    def steps(self, u: np.ndarray, f: np.ndarray, rhs: np.ndarray, refresh: bool, cg: bool, K=None):
        """``x`` ``(n, k)`` with the tangent at ``u`` times ``x`` equal to ``rhs`` ``(n, k)``
        (free DOFs): by conjugate gradients on the current tangent (``cg``, where the full
        tangent is factorised and ``refresh`` is not asked for), else with the kept
        factorisation, or with a fresh one (``refresh``, or where CG fails). ``K``: the full
        tangent at ``u`` where at hand. Returns ``(x, failure or None, whether the tangent was
        factorised, whether CG was slow)``; a failure's ``iterations`` counts the tangent
        assembled for it.
        """
        x, slow = None, False
        if cg and not refresh:
            if K is None:
                _, K = self.assemble(u, f, False)
            x, spent = self.krylov(K, rhs)
            # where CG failed, the tangent moves fast (a contact's set changed): the next step
            # factorises afresh too; measured on a whole-hand grip, letting it try CG on this
            # step's factorisation first saved no factorisation and failed CG twice more
            refresh, slow = x is None, spent >= KRYLOV_ITERATIONS[0]
        if refresh:
            failed = self.refactorise(u, f, K)
            if failed is not None:
                failure = {"ok": False, "reason": failed[0], "iterations": failed[1]}
                return None, failure, True, False
        if x is None:
            try:
                x = self.linear.solve(rhs)
            except RuntimeError as e:
                failure = {"ok": False, "reason": f"linear solve failed: {e}", "iterations": 0}
                return None, failure, refresh, False
        return x, None, refresh, slow
