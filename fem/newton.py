"""Newton's method on a solver's total potential energy (:class:`fem.solver.Solver`).

Each step solves the current tangent ``K du = -r`` through the kept factorisation
(:class:`fem.tangent.Tangent`: conjugate gradients preconditioned by it, or a fresh one), then
backtracks along ``du`` until the energy falls (Armijo, :func:`backtrack`) with every
``det F > 0``. A solve ends converged (the free residual within ``rtol`` of the load), or
failed and saying why: stagnated (the residual stopped halving), an indefinite tangent (the
layer buckles), an inverted element, a line search that cannot lower the energy, or too many
iterations. It never returns a displacement it did not converge to.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

ARMIJO = 1e-4
"""The share of the slope a backtracked step must realise (Armijo's sufficient decrease)."""
HALVINGS = 12
"""Halvings of the step before a line search gives up."""


def backtrack(
    energy_at: Callable[[float], float], E: float, slope: float
) -> tuple[float, float | None]:
    """The first step length ``alpha`` of ``1, 1/2, 1/4, ...`` (:data:`HALVINGS` of them) at
    which ``energy_at(alpha)`` is finite and falls below ``E + ARMIJO alpha slope`` (or rises by
    no more than the energy's round-off), from energy ``E`` with directional derivative
    ``slope`` (< 0): ``(alpha, energy there)``, or ``(0.5 ** HALVINGS, None)`` where none
    does. ``energy_at`` is last called at the step returned.
    """
    alpha = 1.0
    for _ in range(HALVINGS):
        Et = energy_at(alpha)
        if np.isfinite(Et) and (Et <= E + ARMIJO * alpha * slope or (Et - E) <= 1e-12 * abs(E)):
            return alpha, Et
        alpha *= 0.5
    return alpha, None


def _converged(
    solver, u, f, it: int, rel: float, factorisations: int, definite: bool, check: bool
) -> dict:
    """Newton's answer at ``u``; when steps were taken without the pressure stiffness (and
    ``check``: the answer is one, not a start on the way to one), the full tangent must be
    positive definite there (a stable state), else the layer buckles. ``definite`` comes back
    in the answer, for a caller that checks a later solve's.
    """
    if check and definite and solver.tangent.factorise(u, f) is not None:
        return {
            "ok": False,
            "reason": "indefinite tangent at the answer: the layer buckles",
            "iterations": it + 1,
            "residual": rel,
        }
    return {
        "ok": True,
        "u": u,
        "iterations": it,
        "residual": rel,
        "factorisations": factorisations,
        "definite": definite and not check,
    }


def _line_search(solver, u: np.ndarray, f: np.ndarray, step: np.ndarray, E: float, slope: float):
    """:func:`backtrack` along ``step`` from ``u`` of energy ``E`` and directional derivative
    ``slope``: ``(alpha, u + alpha step, its energy)``, or ``(alpha, None, None)`` when no step
    lowers the energy.
    """
    alpha, Et = backtrack(lambda a: solver.energy(u + a * step, f), E, slope)
    if Et is not None:
        return alpha, u + alpha * step, Et
    # Near equilibrium the energy's change falls below its round-off (W sums terms of order
    # mu, or K, to get mu eps^2; a contact's too): a full step that lowers the residual is
    # taken instead.
    trial = u + step
    Et = solver.energy(trial, f)
    if np.isfinite(Et) and abs(Et - E) <= 1e-6 * abs(E):
        r0 = np.linalg.norm(solver.residual(u, f).reshape(-1)[solver.free])
        r1 = np.linalg.norm(solver.residual(trial, f).reshape(-1)[solver.free])
        if r1 < r0:
            return 1.0, trial, Et
    return alpha, None, None


def newton(
    solver,
    u: np.ndarray,
    f: np.ndarray,
    rtol: float | None = None,
    floor: float = 0.0,
    check: bool = True,
    definite: bool = False,
) -> dict:
    """Newton iterations from ``u`` under nodal forces ``f``. With a direct linear solver
    (and ``options.reuse`` above 0) and a factorised full tangent, each step solves the
    current tangent by conjugate gradients preconditioned with the kept factorisation
    (:class:`~fem.tangent.Tangent`; kept from solve to solve), renewed where CG slows.
    Otherwise the factorised tangent is kept while the residual still contracts by
    ``options.reuse`` per step; when a kept factorisation gives no usable step, the tangent
    is assembled and factorised afresh.

    ``check``: whether the answer is checked for stability when steps were taken without the
    pressure stiffness (``False`` for a start on the way to an answer: the answer's
    ``"definite"`` then says whether such steps were taken); ``definite``: such steps were
    taken before this solve, by solves on the way to it that were not checked.
    """
    opt = solver.options
    free = solver.free
    krylov = solver.linear.direct and opt.reuse > 0
    fnorm = max(np.linalg.norm(f.reshape(-1)[free]), 1e-30)
    scale = solver.potentials  # pressed by an object: the contact forces set the scale
    if scale:  # (an object that retracts touches nothing at first: the largest so far)
        fnorm = max(fnorm, *(np.linalg.norm(p.gradient(u)) for p in scale))
    E = solver.energy(u, f)
    history: list[float] = []
    rel, factorisations = float("nan"), 0
    tangent = solver.tangent
    refresh = not (krylov and tangent.factored == "full")
    # steps taken with the tangent less its pressure stiffness (here or on the way here)
    r = solver.residual(u, f)
    for it in range(opt.max_iter + 1):
        rf = r.reshape(-1)[free]
        if scale and it:
            fnorm = max(fnorm, *(np.linalg.norm(p.gradient(u)) for p in scale))
        rel = float(np.linalg.norm(rf) / fnorm)
        history.append(rel)
        if rel <= (rtol or opt.rtol):
            return _converged(solver, u, f, it, rel, factorisations, definite, check)
        if it == opt.max_iter:
            break
        if len(history) > opt.stagnation and history[-1] > 0.5 * history[-1 - opt.stagnation]:
            return {
                "ok": False,
                "reason": f"stagnated: residual {rel:.2e} did not halve in "
                f"{opt.stagnation} iterations",
                "iterations": it,
                "residual": rel,
            }
        conjugate = krylov and tangent.factored == "full"
        if not conjugate and len(history) > 1 and rel > opt.reuse * history[-2]:
            refresh = True
        du, failed, refresh, slow = tangent.direction(u, f, rf, refresh, conjugate)
        if failed is not None:
            return {**failed, "iterations": it + failed["iterations"], "residual": rel}
        factorisations += refresh
        definite |= tangent.factored == "definite"
        fresh, refresh = refresh, False
        slope = float(rf @ du)
        if not np.all(np.isfinite(du)) or slope >= 0:
            if not fresh:  # kept factors gave no descent: refactorise next iteration
                refresh = True
                continue
            return {
                "ok": False,
                "reason": "indefinite tangent: no descent direction",
                "iterations": it + 1,
                "residual": rel,
            }
        step = np.zeros(u.size)
        step[free] = du
        step = step.reshape(-1, 3)
        alpha, trial, Et = _line_search(solver, u, f, step, E, slope)
        if trial is None:
            if not fresh:
                refresh = True
                continue
            if rel <= floor:  # converged as far as round-off lets it
                return _converged(solver, u, f, it + 1, rel, factorisations, definite, check)
            inv = not np.isfinite(solver.energy(u + 2.0**-11 * step, f))
            reason = (
                "element inversion: every step along the Newton direction makes det F <= 0"
                if inv
                else "line search failed to lower the energy"
            )
            return {"ok": False, "reason": reason, "iterations": it + 1, "residual": rel}
        u, E = trial, Et
        r = solver.residual(u, f)
        # CG that slowed renews its preconditioner; without CG, a damped step means the
        # kept tangent has moved on
        refresh = slow if conjugate else alpha < 1.0
    return {
        "ok": False,
        "reason": f"no convergence in {opt.max_iter} iterations (residual {rel:.2e})",
        "iterations": opt.max_iter,
        "residual": rel,
    }
