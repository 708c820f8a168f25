"""Force control: the depth at which a pressed object carries a given force.

The tissue's reaction rises with the depth an object is pushed (:func:`fem.contact.press`);
force control searches for the depth whose reaction is the force asked for, within a relative
tolerance: each try aimed by the power law ``F = c d^p`` through the last two answers, a try that
fails (past the tissue's trust bounds, or a march that cannot go on) halved toward the last
answer, and the search failing with its reason where no depth gets past a failure. Depths in m,
forces in N.
"""

from __future__ import annotations

import time
from dataclasses import replace

import numpy as np

from fem.contact import FLOOR, FORCE_TOLERANCE, HELD, Pressed, Pressing, relax
from fem.newton import backtrack
from fem.shapes import positive

AIM_STEPS = 4
"""Force control aims at most this many marching steps beyond its last answer."""

GAP = 0.02
"""Force control halves a try that failed (past the trust bounds, or a march that could not
go on) toward its last answer, and aims no deeper than the shallowest failure after; it fails
when the last answer lies within this share of that depth of it."""

STATE_FAILURES = ("not trusted", "indefinite tangent", "inverted", "non-physical")
"""Failures of the state at a depth, whatever the way there (past the trust bounds, a layer
that buckles): force control does not try that depth again. Others (a line search that stalls
on the way) may pass on a shorter march."""


def press_to_force(
    solver,
    shape,
    direction,
    force: float,
    rtol: float = 0.01,
    step: float = 0.001,
    stiffness: float | None = None,
    max_updates: int = 20,
    start: Pressed | None = None,
    friction: float = 0.0,
    coupled: bool = True,
) -> Pressed:
    """Push ``shape`` along ``direction`` until the reaction is ``force`` (N) within ``rtol``.

    ``coupled`` (frictionless, along a direction): from an answer in contact (``start``, or
    the first from rest that touches) the depth is solved together with the displacement in
    one Newton system (:func:`_coupled`), its equation the reaction equal to ``force``, which
    it then meets to the solver's tolerance; where that cannot go on, the search below takes
    over, its first try at the depth the Newton system had reached (:func:`_searched`). The
    search:
    the depth rises from the placed pose, or from ``start`` (an answer of the same object and
    solver carrying less than ``force``), each try aimed at the force by the power law through
    the last two answers and at most :data:`AIM_STEPS` steps of ``step`` (m) ahead, until the
    reaction passes the force; then the depth is found between the last two answers (each try
    marched from the nearer one). A try that fails, past the tissue's trust bounds
    (:class:`~fem.limits.Limits`) or in a march that cannot go on, is halved toward the last
    answer, and no later try aims at or past the shallowest failure: the search fails, saying
    why and after what force, once its last answer lies within :data:`GAP` of that depth (a
    march that stalled there is first tried once more with one step past it), or
    when the force falls as the object goes deeper (a grip slipping). Inside the bracket a failed
    try is replaced by its middle and quarters. A press that runs through the whole tissue
    fails too. ``friction``: Coulomb's coefficient between object and skin
    (:mod:`fem.friction`; each try's answer then depends on the answer it was marched from).
    The answer's ``time`` is the whole search's.
    """
    force = positive(force, "target force")
    if not 0 < rtol < 0.5:
        raise ValueError(f"rtol must lie in (0, 0.5), got {rtol!r}")
    if start is not None and not (start.ok and start.reaction < force):
        raise ValueError(f"start must be an answer that carries less than {force:g} N")
    t0 = time.perf_counter()
    answer = _force_control(
        solver,
        shape,
        direction,
        force,
        rtol,
        step,
        stiffness,
        max_updates,
        start,
        friction,
        coupled,
    )
    return replace(answer, time=time.perf_counter() - t0)


def press_to_forces(
    solver,
    shape,
    direction,
    forces,
    on_answer=None,
    friction: float = 0.0,
    coupled: bool = True,
    start: Pressed | None = None,
    rtol: float = 0.01,
) -> list[Pressed]:
    """:func:`press_to_force` to each of ``forces`` (N, rising) in turn, each from the last
    answer (the first from ``start``: an earlier answer of the same press, or rest); after a
    failure the rest are failed as skipped. ``on_answer(force, answer)``: called as each ends (a
    progress report); ``friction``, ``coupled`` and ``rtol`` as for :func:`press_to_force`.
    """
    out, last, failed = [], start, None
    for f in forces:
        if failed is None:
            a = press_to_force(
                solver,
                shape,
                direction,
                float(f),
                rtol=rtol,
                start=last,
                friction=friction,
                coupled=coupled,
            )
            last, failed = (a, None) if a.ok else (last, f)
        else:
            a = Pressed(False, f"skipped: {failed:g} N failed", float("nan"))
        out.append(a)
        if on_answer is not None:
            on_answer(f, a)
    return out


def _aim(a: Pressed, b: Pressed, force: float) -> float:
    """The depth (m) at which ``force`` (N) lies on the power law ``F = c d^p`` through answers
    ``a`` and ``b`` (the force-depth curve of an indenter on soft tissue: ``p`` 1 for a flat
    punch on a thin layer, 1.5 for a sphere (Hertz), more as the tissue stiffens), ``p`` kept
    within [1, 4]; from rest (``a`` at 0) Hertz's 1.5. Where ``b`` carries nothing yet (the
    object has not touched), infinitely deep: the caller's reach bounds the next try.
    """
    if not b.reaction > 0:
        return np.inf
    if a.depth > 0 and a.reaction > 0 and b.reaction > 0 and b.reaction != a.reaction:
        p = np.log(b.reaction / a.reaction) / np.log(b.depth / a.depth)
    else:
        p = 1.5
    p = min(max(float(p), 1.0), 4.0)
    return float(b.depth * (force / b.reaction) ** (1.0 / p))


def _force_control(
    solver, shape, direction, force, rtol, step, stiffness, max_updates, start, friction, coupled
):
    """:func:`press_to_force`'s work, its arguments checked."""
    with Pressing(solver, shape, direction, stiffness, 2e-3, max_updates, step, friction) as go:
        if coupled and not friction and direction is not None:
            if start is None:  # from rest: a step at a time until the object touches
                start = _first_touch(go, step)
                if start is not None and abs(start.reaction - force) <= rtol * force:
                    return start
            if start is not None and start.reaction > 0:
                answer, reached = _coupled(go, force, start)
                if answer is not None:
                    return answer
                return _searched(go, force, rtol, step, start, reached)
        got = _bracket(go, force, rtol, step, start)
        return _between(go, force, rtol, *got) if isinstance(got, tuple) else got


def _first_touch(go, step: float) -> Pressed | None:
    """The first answer that carries a force, from rest a ``step`` (m) deeper at a time (an
    object that touches nothing costs no solve); ``None`` where a try fails or the object
    reaches the bone first (the search then says why).
    """
    deepest = float(go.solver.mesh.thickness.max())
    depth = 0.0
    while depth < deepest:
        depth = min(depth + step, deepest)
        answer = go.to(depth, None)
        if not answer.ok:
            return None
        if answer.reaction > 0:
            return answer
    return None


COUPLED_STAGNATION = 10
"""Newton's method on the depth and the displacement hands over to the search when its residual
does not halve in this many iterations (where the skin slips round a rounded rim its tangent,
the contact's penalty stiffness without the rim's curvature, is stiffer than the energy, and
the residual creeps from some 1e-3 of the contact force: docs/tissue.md)."""


def _coupled(go, force: float, start: Pressed) -> tuple[Pressed | None, float | None]:
    """Force control in one Newton system: from ``start`` (an answer in contact, carrying more
    or less than ``force``) the object's depth ``d`` is an unknown beside the displacement, and
    the energy less ``force d`` is minimised over both (:func:`_newton_on_depth`), so that its
    stationary point carries ``force`` exactly; the multipliers are updated as in a press.
    Returns ``(answer, reached)``: the answer, or ``None`` and the depth (m) the solve had
    reached where it stopped (``None`` if it took no step, or its answer is not trusted: the
    search then finds where).
    """
    solver, contact = go.solver, go.contact
    tolerance, max_updates, _ = go.options
    t0 = time.perf_counter()
    contact.multipliers = start.multipliers.copy()
    at = {"depth": start.depth}

    def solve(v, rtol, floor, check, definite):
        res = _newton_on_depth(go, v, at["depth"], force, rtol, floor, check, definite)
        at["depth"] = res.get("depth", at["depth"])
        return res

    aimed = start.depth * (force / start.reaction) ** (2 / 3)  # Hertz's law: the depth's scale
    deep = tolerance * max(aimed, start.depth)  # the penetration allowed, m
    res = relax(solver, contact, start.state, deep, max_updates, False, None, solve)
    if not res["ok"]:
        return None, (at["depth"] if res["iterations"] else None)
    answer = go.answer(res["u"], at["depth"], res, t0)
    return (answer, None) if answer.ok else (None, None)


def _searched(go, force: float, rtol: float, step: float, start: Pressed, reached):
    """The search over depths where the one system could not answer: first a press to the
    depth it had ``reached`` (m), marched from ``start`` (from its last iterate, nearly in
    equilibrium, a press at 10 N on the belly did not converge where the march did), then the
    bracket from the nearest answers below and above ``force`` (rest below where ``start``
    already carries more).
    """
    below = start if start.reaction < force else Pressed(True, "", 0.0, reaction=0.0)
    above = None if start.reaction < force else start
    if reached is not None and reached > 0:
        tried = go.to(reached, start)
        if tried.ok and abs(tried.reaction - force) <= rtol * force:
            return tried
        if tried.ok and tried.reaction < force and tried.depth > below.depth:
            below = tried
        elif tried.ok and tried.reaction > force and (above is None or tried.depth < above.depth):
            above = tried
    if above is not None:
        return _between(go, force, rtol, below, above)
    got = _bracket(go, force, rtol, step, below if below.depth > 0 else None)
    return _between(go, force, rtol, *got) if isinstance(got, tuple) else got


def _converged(tangent, u, zero, K, out: dict, factorisations: int, definite, check) -> dict:
    """The one system's answer at ``u`` (tangent ``K``), checked as
    :func:`fem.newton._converged` checks a press's.
    """
    if check and definite and tangent.factorise(u, zero, K=K) is not None:
        reason = "indefinite tangent at the answer: the layer buckles"
        return {**out, "ok": False, "reason": reason, "iterations": out["iterations"] + 1}
    found = {**out, "ok": True, "u": u, "factorisations": factorisations}
    return {**found, "definite": definite and not check}


def _newton_on_depth(
    go,
    u,
    depth: float,
    force: float,
    rtol: float,
    floor: float = FLOOR,
    check: bool = True,
    definite: bool = False,
):
    """Newton's method on the displacement ``u`` and the object's depth ``depth`` (m) together,
    at fixed contact multipliers: the energy ``Pi(u, d) = W(u) + C(u, d) - force d`` minimised,
    so that at its answer the tissue is in equilibrium and the reaction ``dC/dd`` is ``force``.
    Each step solves the bordered system ``[K b; b^T c] [du; dd] = -[r; R - force]`` through
    the tangent ``K``'s factorisation (two right-hand sides: the residual and ``b``, the
    contact's mixed derivative; :meth:`fem.contact.Contact.coupling`), and a backtracking line
    search on ``Pi`` keeps each a descent. Converged where the residual is within ``rtol`` of
    the contact forces and the reaction within ``rtol`` of ``force``; ``floor`` as for
    :meth:`fem.solver.Solver.equilibrium`, and ``check`` and ``definite`` (whether the answer's
    stability is checked; solves on the way to it that stepped without the pressure stiffness).
    Returns the solver's dict with ``depth`` beside ``u`` (failed: the depth it had reached);
    the contact is left at the answer's pose.
    """
    solver, contact, shape, e = go.solver, go.contact, go.shape, go.direction
    free, opt, tangent = solver.free, solver.options, solver.tangent
    zero = np.zeros_like(u)

    def energy(v, d):
        contact.shape = shape.pushed(d, e)
        return solver.energy(v, zero) - force * d

    E, scale, history, factorisations = energy(u, depth), 0.0, [], 0
    krylov = solver.linear.direct and opt.reuse > 0
    refresh = not (krylov and tangent.factored == "full")
    for it in range(opt.max_iter + 1):
        contact.shape = shape.pushed(depth, e)
        r, K = solver.assemble(u, zero)
        b, c, reaction, norm = contact.coupling(u, e)
        scale = max(scale, norm, 1e-30)
        rf, bf, rd = r.reshape(-1)[free], b.reshape(-1)[free], reaction - force
        rel = max(float(np.linalg.norm(rf)) / scale, abs(rd) / force)
        history.append(rel)
        out = {"iterations": it, "residual": rel, "depth": depth}
        if rel <= rtol:
            return _converged(tangent, u, zero, K, out, factorisations, definite, check)
        if it == opt.max_iter:
            break
        patience = COUPLED_STAGNATION
        if len(history) > patience and rel > 0.5 * history[-1 - patience]:
            reason = f"stagnated: residual {rel:.2e} did not halve in {patience} iterations"
            return {**out, "ok": False, "reason": reason}
        cg = krylov and tangent.factored == "full"
        rhs = np.stack([-rf, bf], axis=1)
        y, failed, fresh, refresh = tangent.steps(u, zero, rhs, refresh or not cg, cg, K)
        if failed is not None:
            return {**out, **failed, "iterations": it + failed["iterations"]}
        factorisations += fresh
        definite |= tangent.factored == "definite"
        stiffness = c - bf @ y[:, 1]  # the reaction's rise with depth, N/m (the Schur complement)
        dd = (-rd - bf @ y[:, 0]) / stiffness if stiffness > 0 else np.nan
        du = y[:, 0] - y[:, 1] * dd
        slope = float(rf @ du + rd * dd)
        if not (np.isfinite(slope) and slope < 0):
            if not fresh:  # the kept factorisation gave no descent: a fresh one
                refresh = True
                continue
            reason = "indefinite tangent: the reaction does not rise with the depth"
            return {**out, "ok": False, "reason": reason, "iterations": it + 1}
        step = np.zeros(u.size)
        step[free] = du
        step = step.reshape(-1, 3)
        alpha, Et = backtrack(lambda a: energy(u + a * step, depth + a * dd), E, slope)
        if Et is None:
            contact.shape = shape.pushed(depth, e)
            if not fresh:
                refresh = True
                continue
            if rel <= floor:  # converged as far as round-off lets it
                return _converged(tangent, u, zero, K, out, factorisations, definite, check)
            reason = "line search failed to lower the energy"
            return {**out, "ok": False, "reason": reason, "iterations": it + 1}
        u, depth, E = u + alpha * step, depth + alpha * dd, Et
        refresh = refresh or (fresh and alpha < 1.0)
    out = {"iterations": opt.max_iter, "residual": rel, "depth": depth}
    reason = f"no convergence in {opt.max_iter} iterations (residual {rel:.2e})"
    return {**out, "ok": False, "reason": reason}


def _bracket(go, force: float, rtol: float, step: float, start: Pressed | None):
    """Force control's first phase: deeper from ``start`` (or rest) until an answer carries
    more than ``force``. Returns ``(below, above)``, or the answer that meets the force, or the
    failure that ends the search.
    """
    deepest = float(go.solver.mesh.thickness.max())
    reach = AIM_STEPS * step  # how far ahead of the last answer a try may aim
    lo = start or Pressed(True, "", 0.0, reaction=0.0)
    depth = min(lo.depth + step, deepest)
    jumped = False
    # the shallowest failed try, the start it failed from, and whether a nearer start may pass
    ceiling, since, path, failure = np.inf, 0.0, False, None
    stuck = None  # a march failure force control tries to jump past, once
    while True:
        answer = go.to(depth, lo if lo.depth > 0 else None)
        if not answer.ok and stuck is not None:  # the jump failed too
            return stuck
        if not answer.ok and answer.reason.startswith(HELD):
            return _stuck(force, answer, depth, lo)
        if not answer.ok:  # past the trust bounds, or a march that could not go on
            ceiling, since, failure = depth, lo.depth, answer
            path = not answer.reason.startswith(STATE_FAILURES)
            if ceiling - lo.depth > GAP * ceiling:
                depth = 0.5 * (lo.depth + ceiling)  # halve the way toward the last answer
                continue
            if not path or jumped:
                return _stuck(force, failure, ceiling, lo)
            # a march stalled just past the last answer: one step from it that lands beyond
            # (a contact whose nodes come and go may stall a Newton solve at one depth only)
            stuck, jumped = _stuck(force, failure, ceiling, lo), True
            depth = min(max(lo.depth + step, (1 + 2 * GAP) * ceiling), deepest)
            ceiling, path, failure = np.inf, False, None
            continue
        stuck = None
        if path and ceiling - answer.depth <= GAP * ceiling and since < answer.depth:
            # close below a march that failed from farther away: a short one may pass
            ceiling, since, path, failure = np.inf, answer.depth, False, None
        if abs(answer.reaction - force) <= rtol * force:
            return answer
        if answer.reaction > force:
            return lo, answer
        if lo.depth > 0 and answer.reaction < lo.reaction * (1 - FORCE_TOLERANCE):
            return replace(  # e.g. a hand's fingers slipping round the limb as it closes
                answer,
                ok=False,
                displacement=None,
                reason=f"cannot carry {force:g} N: the force falls as the object goes deeper "
                f"({lo.reaction:.3g} N at {1e3 * lo.depth:.2f} mm, {answer.reaction:.3g} N at "
                f"{1e3 * answer.depth:.2f} mm)",
            )
        lo, before = answer, lo
        if failure is not None and ceiling - lo.depth <= GAP * ceiling:
            return _stuck(force, failure, ceiling, lo)  # as close to the failure as it gets
        depth = min(_aim(before, lo, force), lo.depth + reach, deepest, ceiling)
        if depth >= ceiling:  # not again where a try failed: halfway to it
            depth = 0.5 * (lo.depth + ceiling)
        if depth <= lo.depth * (1 + 1e-9):
            return replace(
                lo,
                ok=False,
                displacement=None,
                reason=f"cannot carry {force:g} N: the object reached the bone "
                f"({1e3 * deepest:.1f} mm) at {lo.reaction:.3g} N",
            )


def _between(go, force: float, rtol: float, lo: Pressed, hi: Pressed) -> Pressed:
    """Force control's second phase: the depth between answers ``lo`` and ``hi`` that carries
    ``force``, aimed by the power law through them; a try that fails is replaced by the
    bracket's middle and quarters. Each try marches from the nearer answer, or with friction
    from ``lo``: a frictional answer depends on the way it was reached, and the object closes
    on the skin, never backs off it (from ``hi`` the skin would slip back under the fingers).
    """
    failed, answer = [], hi  # shares of the bracket whose tries failed
    for _ in range(30):
        aim = _aim(lo, hi, force) if lo.depth > 0 else 0.5 * hi.depth
        w = min(max((aim - lo.depth) / (hi.depth - lo.depth), 0.05), 0.95)
        if failed:  # a try inside the bracket failed: another share of it
            w = next((x for x in (0.5, 0.25, 0.75) if x not in failed), None)
            if w is None:
                return replace(answer, reason=f"cannot carry {force:g} N: {answer.reason}")
        depth = lo.depth + w * (hi.depth - lo.depth)
        if go.friction:  # the loading path's answer, from below (rest while lo is at rest)
            near = lo if lo.depth > 0 else None
        else:  # the elastic answer does not depend on the path: the shorter march
            near = lo if (depth - lo.depth <= hi.depth - depth and lo.depth > 0) else hi
        answer = go.to(depth, near)
        if not answer.ok:
            failed.append(w)
            continue
        if abs(answer.reaction - force) <= rtol * force:
            return answer
        failed = []
        lo, hi = (answer, hi) if answer.reaction < force else (lo, answer)
    return replace(answer, ok=False, displacement=None, reason="force control did not settle")


def _stuck(force: float, failure: Pressed, depth: float, last: Pressed) -> Pressed:
    """Force control's failure where it cannot get past ``failure`` at ``depth`` (m)."""
    return replace(
        failure,
        reason=f"cannot carry {force:g} N: {failure.reason} at depth {1e3 * depth:.2f} mm, "
        f"after {last.reaction:.3g} N",
    )
