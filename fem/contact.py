"""Rigid objects pressed into the tissue: frictionless contact by an augmented Lagrangian.

An object is a rigid shape with a signed distance ``phi`` (m; positive outside it) and its
gradient, the object's outward normal. It is placed by a pose and pressed along a direction by
a prescribed depth; the skin's nodes may not enter it. Each skin node ``i`` carries a share
``w_i`` of the skin's area (m^2) and a contact pressure ``lambda_i`` (Pa). For a fixed
``lambda`` the solver minimises the elastic energy plus

    sum_i w_i / (2 k) (max(0, lambda_i - k phi_i)^2 - lambda_i^2)

(penalty stiffness ``k`` in Pa/m), then updates ``lambda_i <- max(0, lambda_i - k phi_i)`` until
the deepest penetration is below a tolerance (Uzawa's iteration; with ``lambda = 0`` it is the
plain penalty method). The contact pressure is ``lambda`` where the skin touches, and the
reaction force, the force the object must be pushed with, is the sum of ``w_i lambda_i`` along
the object's normals.

The shapes live in :mod:`fem.shapes`: the exact :class:`~fem.shapes.Sphere`,
:class:`~fem.shapes.Punch` and :class:`~fem.shapes.Box`, and any triangle mesh
(:class:`~fem.shapes.Surface`: a user's object, anny's hand, which may close along a grip's
path instead of moving along one direction). Lengths in m, pressures in Pa, forces in N.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field, replace

import numpy as np

from fem.elements import TRI_EDGES
from fem.friction import Friction, motion
from fem.shapes import positive, unit


def skin_weights(solver) -> tuple[np.ndarray, np.ndarray]:
    """``(nodes (K,), weights (K,))``: the skin's nodes (corners, and the edge nodes of
    quadratic elements) and the share of the skin's area (m^2) each carries. A quadratic skin
    triangle is split at its edge nodes into four, each sharing its area among its corners.
    """
    mesh = solver.mesh
    tri = mesh.skin_faces
    area = mesh.skin_face_areas
    if solver.order == 1:
        w = np.bincount(tri.ravel(), np.repeat(area / 3, 3), minlength=mesh.n_skin)
        return np.arange(mesh.n_skin), w
    key = solver.edges[:, 0] * solver.n_all + solver.edges[:, 1]
    te = np.sort(tri[:, TRI_EDGES], axis=2)
    mid = mesh.n_nodes + np.searchsorted(key, te[..., 0] * solver.n_all + te[..., 1])
    w = np.bincount(tri.ravel(), np.repeat(area / 12, 3), minlength=solver.n_all)
    w += np.bincount(mid.ravel(), np.repeat(area / 4, 3), minlength=solver.n_all)
    nodes = np.flatnonzero(w > 0)
    return nodes, w[nodes]


class Contact:
    """One object's contact with the skin of ``solver``'s mesh, as a potential the solver adds
    to its energy (see the module docstring). ``stiffness``: the penalty ``k``, Pa/m.
    """

    def __init__(self, solver, shape, stiffness: float):
        self.solver = solver
        self.shape = shape
        self.stiffness = positive(stiffness, "contact stiffness")
        self.nodes, self.weights = skin_weights(solver)
        self.multipliers = np.zeros(len(self.nodes))
        self.held = solver.fixed[self.nodes].all(axis=1)  # skin nodes held in place (a rim)
        self.held_inside = 0.0
        self.rest = solver.positions[self.nodes]
        self._last = None  # (shape, positions, distance) of the last distance computed

    def _distance(self, u: np.ndarray):
        """The object's ``(phi, grad, curvature)`` at the skin nodes displaced by ``u``: a
        Newton step asks for it at one state several times (the residual, the tangent, the
        coupling, the line search's energy), so the last one is kept, read-only, and given
        again for the same object and the same positions.
        """
        x = self.rest + u[self.nodes]
        last = self._last
        if last is not None and last[0] is self.shape and np.array_equal(last[1], x):
            return last[2]
        found = self.shape.distance(x)
        for a in found:
            if a is not None:
                a.flags.writeable = False
        self._last = (self.shape, x, found)
        return found

    def _state(self, u: np.ndarray):
        phi, grad, curv = self._distance(u)
        p = np.maximum(self.multipliers - self.stiffness * phi, 0.0)
        return phi, grad, curv, p

    def energy(self, u: np.ndarray) -> float:
        """The contact potential at displacement ``u`` ``(n_all, 3)``, J."""
        _, _, _, p = self._state(u)
        lam = self.multipliers
        return float(np.sum(self.weights * (p**2 - lam**2)) / (2 * self.stiffness))

    def gradient(self, u: np.ndarray) -> np.ndarray:
        """``(n_all, 3)``: the potential's gradient, N (minus the contact forces on the skin)."""
        _, grad, _, p = self._state(u)
        out = np.zeros((self.solver.n_all, 3))
        out[self.nodes] = -(self.weights * p)[:, None] * grad
        return out

    def hessian(self, u: np.ndarray):
        """The potential's Hessian node by node, ``(rows, cols, values)`` over DOF indices
        ``3 node + i``: its positive part ``k w n n^T`` only. The curvature term of a curved
        object, ``-w p grad^2 phi``, is left out: it softens the tissue sideways and can make the
        tangent indefinite under a fingertip; without it Newton's steps stay descent steps.
        """
        _, grad, _, p = self._state(u)
        on = p > 0
        w = self.weights[on]
        H = self.stiffness * w[:, None, None] * grad[on, :, None] * grad[on, None, :]
        nodes = self.nodes[on]
        i, k = np.divmod(np.arange(9), 3)
        rows = (3 * nodes[:, None] + i).ravel()
        cols = (3 * nodes[:, None] + k).ravel()
        return rows, cols, H.reshape(-1)

    def coupling(self, u: np.ndarray, direction: np.ndarray):
        """The potential's terms in the object's depth ``d`` along ``direction`` ``(3,)`` (the
        object moved as ``d`` rises: ``phi(x - d e)``), for force control in one Newton system:
        ``(b (n_all, 3), c, reaction, scale)`` with ``b`` the mixed second derivative
        ``d^2/du dd`` (N/m), ``c`` the second derivative in ``d`` (N/m; both their positive parts,
        as :meth:`hessian`), ``reaction = dE/dd`` (N: the force the object must be pushed with)
        and ``scale`` the norm of the contact forces on the skin's nodes (N).
        """
        _, grad, _, p = self._state(u)
        on = p > 0
        along = grad[on] @ direction  # each pressed node's normal along the press
        kw = self.stiffness * self.weights[on]
        b = np.zeros((self.solver.n_all, 3))
        b[self.nodes[on]] = -(kw * along)[:, None] * grad[on]
        reaction = float(np.sum(self.weights[on] * p[on] * along))
        return b, float(np.sum(kw * along**2)), reaction, float(np.linalg.norm(self.weights * p))

    def update(self, u: np.ndarray) -> tuple[float, float]:
        """Uzawa's step at the equilibrium ``u``: the multipliers become the contact pressures
        that hold it (and what :meth:`pressures` and :meth:`force` report). Returns the deepest
        penetration (m) and the share of the contact force the next update would still change:
        ``k`` times each pressed node's penetration, and the pressure left on nodes that have
        come away from the object (an object that retracts leaves them). :attr:`held_inside`
        becomes the deepest a held node (which no force moves) lies inside the object, m.
        """
        phi, grad, _, p = self._state(u)
        self.multipliers = p
        self._normals = grad
        inside = np.maximum(-phi, 0.0) * (p > 0)
        self.held_inside = float(inside[self.held].max(initial=0.0))
        following = np.maximum(p - self.stiffness * phi, 0.0)
        held = float(np.sum(self.weights * np.abs(following - p)))
        total = float(np.sum(self.weights * p))
        return float(inside.max(initial=0.0)), held / total if total > 0 else 0.0

    def pressures(self) -> np.ndarray:
        """``(K,)`` contact pressure on each skin node of :attr:`nodes` at the last update, Pa."""
        return self.multipliers

    def force(self) -> np.ndarray:
        """``(3,)`` the force the skin exerts on the object at the last update, N (the object's
        reaction).
        """
        return -np.sum((self.weights * self.multipliers)[:, None] * self._normals, axis=0)


RTOL = 1e-6
"""Newton's relative residual under contact: a skin node on the edge of the contact comes and
goes between iterations, and the residual stalls near 1e-6 of the contact force (its share of
the reaction is far below :data:`FORCE_TOLERANCE`)."""

PATIENCE = {"stagnation": 25, "max_iter": 80, "max_substeps": 5}
"""Newton's patience under contact (at least these, whatever the solver's options): as a
hand's grip closes, contact nodes come and go and the residual may take twenty iterations to
halve, where a press without contact fails after six (a pinch on the forearm stalled at 2.6 N
with six and reached 8.8 N with these)."""

FLOOR = 1e-4
"""Where Newton's line search can no longer lower the energy under contact (a hand's many
contact nodes, each on the edge of touching), a residual this small of the contact force is
converged: a tenth of :data:`FORCE_TOLERANCE`."""

STEP_RTOL = 1e-4
"""Newton's relative residual on the way to a pose (the steps before its last), with one
multiplier update each: a start for the next step, not an answer."""

UZAWA_RTOL = STEP_RTOL
"""Newton's relative residual while the multipliers still move (Uzawa's iteration solved
inexactly, :func:`relax`); the answer's own solve is to :data:`RTOL`. On a grip's force it
took the Newton iterations from 68 to 49 with the same answer (docs/tissue.md)."""

HELD = "the object presses the part's held rim"
"""The failure of a press whose object reaches skin the FEM holds in place (the part's cut
rims): no depth gets past it, so force control stops at once."""

FORCE_TOLERANCE = 1e-3
"""Multiplier updates go on until the penetration left would add less than this share to the
contact force."""


def stiffest_modulus(material) -> float:
    """The largest initial Young's modulus (Pa) among a material's laws (one, or a layer's each)."""
    laws = getattr(material, "laws", (material,))
    return max(float(law.E) for law in laws)


def default_stiffness(solver) -> float:
    """A penalty stiffness, Pa/m: 100 times the stiffest law's Young's modulus over the skin's
    short edges (the 5th percentile; an element's own stiffness is about E / edge, and meshes
    are finest where objects press): a first solve leaves about a hundredth of the depth as
    penetration, and each multiplier update removes most of what is left.
    """
    mesh = solver.mesh
    tri = mesh.skin_faces
    edges = np.linalg.norm(mesh.nodes[tri] - mesh.nodes[np.roll(tri, 1, axis=1)], axis=2)
    return 100.0 * stiffest_modulus(solver.material) / float(np.percentile(edges, 5))


@dataclass(frozen=True, eq=False)
class Pressed:
    """The answer to one depth of a pressed object.

    Attributes:
        ok: whether the solve converged (and the state is physical); else ``reason`` says why
            and no displacement is given.
        depth: how far the object was pushed from its placed pose, m.
        displacement: ``(N, 3)`` on the vertices of the part the solver answers on
            (:attr:`fem.solver.Solver.answer_on`), m (``None`` when failed).
        state: ``(n_all, 3)`` every node's displacement, for a warm start.
        reaction: the force the object must be pushed with along its direction, N; for a
            mesh closing along a path (a grip), the total contact force.
        total: the sum of the normal contact forces over the skin, N (a grip's squeeze).
        force: ``(3,)`` the force the skin exerts on the object, N (its friction's part
            in).
        friction: ``(3,)`` the friction's part of ``force``, N (zero without friction).
        pressure: ``(N,)`` contact pressure on that part's vertices, Pa.
        push: ``(N,)`` the contact pressure's part along the press direction on that part's
            vertices, Pa: the reaction's density (times the vertices' areas it sums to
            ``reaction``; a grip's, the pressure itself).
        area: contact area, m^2 (the skin area the object presses).
        penetration: the deepest a skin node lies inside the object, m.
        min_det_F: the smallest volume ratio in the tissue; ``compression``: how far the skin
            moves inward as a share of the tissue's depth under it (its largest).
        iterations: Newton iterations, all updates summed; ``updates``: multiplier updates.
        time: seconds the answer took (under force control, the whole search).
    """

    ok: bool
    reason: str
    depth: float
    displacement: np.ndarray | None = None
    state: np.ndarray | None = None
    reaction: float = float("nan")
    total: float = float("nan")
    force: np.ndarray | None = None
    friction: np.ndarray | None = None
    pressure: np.ndarray | None = None
    push: np.ndarray | None = None
    area: float = float("nan")
    penetration: float = float("nan")
    min_det_F: float = float("nan")
    compression: float = float("nan")
    iterations: int = 0
    updates: int = 0
    time: float = 0.0
    multipliers: np.ndarray | None = field(default=None, repr=False)


def relax(
    solver,
    contact,
    u,
    tolerance: float,
    max_updates: int,
    on_the_way=False,
    friction=None,
    solve=None,
) -> dict:
    """Equilibrium at the contact's current pose, the multipliers updated until the deepest
    penetration is within ``tolerance`` (m) and the pressure the penetration still holds back
    is within :data:`FORCE_TOLERANCE` of the contact force (and, with ``friction``, until its
    lagged pressures change by less than that). ``on_the_way``: a step towards a deeper pose,
    solved to :data:`STEP_RTOL` with one multiplier update (what it leaves, the next step's
    solve removes). ``solve(u, rtol, floor, check, definite) -> dict``: the equilibrium at
    fixed multipliers (default the solver's; force control's moves the object too, leaving the
    contact at its answer's pose; ``check`` and ``definite`` as for
    :meth:`fem.solver.Solver.equilibrium`).

    Uzawa's iteration solved inexactly: while the multipliers still move, each equilibrium
    is solved to :data:`UZAWA_RTOL` only (its error in the multipliers is far below
    :data:`FORCE_TOLERANCE`), and its stability is not checked; once an update meets the
    tolerances, the equilibrium is solved to the answer's residual, checked, and the
    multipliers updated and judged once more.
    """
    iters = 0
    tight = max(solver.options.rtol, RTOL)
    loose = max(tight, UZAWA_RTOL)
    exact = loose == tight  # every solve is to the answer's residual: each is checked
    definite = False  # a solve not checked stepped without the pressure stiffness
    if solve is None:

        def solve(u, rtol, floor, check, definite):
            return solver.equilibrium(u, np.zeros_like(u), rtol, floor, check, definite)

    for k in range(max_updates + 2):
        if k > max_updates and not exact:  # (one more solve for the answer's residual)
            break
        final = exact and not on_the_way
        res = solve(u, tight if final else loose, FLOOR, final, definite)
        iters += res["iterations"]
        if not res["ok"]:
            return {**res, "iterations": iters, "updates": k}
        definite |= res.get("definite", False)
        u = res["u"]
        gap, left = contact.update(u)
        if friction is not None:
            left = max(left, friction.relag())
        if contact.held_inside > tolerance:
            return {
                "ok": False,
                "reason": f"{HELD}: {1e3 * contact.held_inside:.3f} mm inside the object, the "
                "part's cut, held in place, cannot give way (place the object farther from it)",
                "iterations": iters,
                "updates": k + 1,
            }
        if on_the_way:
            return {**res, "u": u, "iterations": iters, "updates": 1, "penetration": gap}
        if gap <= tolerance and left <= FORCE_TOLERANCE:
            if final:
                return {**res, "u": u, "iterations": iters, "updates": k + 1, "penetration": gap}
            exact = True  # met on a loose solve: the next one is the answer's
    return {
        "ok": False,
        "reason": f"contact: penetration {gap:.2e} m (tolerance {tolerance:.1e} m) still holds "
        f"back {100 * left:.2f} % of the force after {max_updates} multiplier updates",
        "iterations": iters,
        "updates": max_updates,
    }


def press(
    solver,
    shape,
    direction,
    depths,
    stiffness: float | None = None,
    tolerance: float = 2e-3,
    max_updates: int = 20,
    max_step: float = 0.001,
    friction: float = 0.0,
) -> list[Pressed]:
    """Push ``shape`` (placed by its pose) along ``direction`` ``(3,)`` to each of ``depths``
    (m, rising) into ``solver``'s tissue (a :class:`~fem.shapes.Surface` with a path closes
    along it, ``direction`` ``None``), each depth warm-started from the last in steps of at
    most ``max_step`` (m); a step that fails is retried in up to ``solver.options.max_substeps``
    halvings, and the depths after a failure are reported as skipped.

    ``stiffness``: the penalty, Pa/m (default :func:`default_stiffness`); ``tolerance``: the
    deepest penetration allowed, as a share of the depth (default 0.2 %); ``friction``: the
    coefficient of Coulomb's friction between object and skin (:mod:`fem.friction`; 0, the
    default, is frictionless).
    """
    depths = [float(d) for d in depths]
    if not depths or any(not np.isfinite(d) or d < 0 for d in depths):
        raise ValueError(f"depths must be finite and >= 0 m, got {depths}")
    if any(b <= a for a, b in zip(depths, depths[1:])):
        raise ValueError(f"depths must rise strictly, got {depths}")
    with Pressing(
        solver, shape, direction, stiffness, tolerance, max_updates, max_step, friction
    ) as go:
        return _in_turn(go, depths, None, "skipped: a smaller depth ({:.3g} m) failed")


def slide(
    solver,
    shape,
    direction,
    depth: float,
    across,
    distances,
    friction: float,
    stiffness: float | None = None,
    max_updates: int = 20,
    max_step: float = 0.001,
) -> list[Pressed]:
    """Press ``shape`` ``depth`` (m) along ``direction`` ``(3,)``, then draw it along ``across``
    ``(3,)`` (a tangent: across the skin) by each of ``distances`` (m, rising), each from the
    last, with Coulomb's ``friction`` (:mod:`fem.friction`). Each answer's ``depth`` is the
    distance drawn and its ``reaction`` the pull the object needs along ``across`` (N), its
    ``total`` the normal contact force; the first answer is the press. A failure skips the rest.
    """
    distances = [float(d) for d in distances]
    if not distances or any(not np.isfinite(d) or d <= 0 for d in distances):
        raise ValueError(f"distances must be finite and > 0 m, got {distances}")
    if any(b <= a for a, b in zip(distances, distances[1:])):
        raise ValueError(f"distances must rise strictly, got {distances}")
    (pressed,) = press(
        solver, shape, direction, [depth], stiffness, max_updates=max_updates, friction=friction
    )
    out = [pressed]
    if not pressed.ok:
        return out + [Pressed(False, "skipped: the press failed", d) for d in distances]
    at = shape.pushed(depth, unit(direction))
    tolerance = 2e-3 * depth / distances[-1]  # the press's penetration allowed, as a share
    with Pressing(
        solver, at, across, stiffness, min(tolerance, 0.5), max_updates, max_step, friction
    ) as go:
        start = replace(pressed, depth=0.0)
        return out + _in_turn(go, distances, start, "skipped: a shorter slide ({:.3g} m) failed")


def _in_turn(go: "Pressing", depths: list[float], start, skipped: str) -> list["Pressed"]:
    """``go``'s answers at each of ``depths`` (m), each marched from the last answer
    (``start`` before the first; ``None``: rest); after a failure the rest are skipped, each
    with ``skipped`` formatted with the failed depth.
    """
    out, failed = [], None
    for depth in depths:
        if failed is not None:
            out.append(Pressed(False, skipped.format(failed), depth))
            continue
        answer = go.to(depth, start)
        out.append(answer)
        if answer.ok:
            start = answer
        else:
            failed = depth
    return out


class Pressing:
    """A contact on ``solver`` for the length of a ``with`` block (with Coulomb's friction of
    coefficient ``friction`` when it is above zero); :meth:`to` answers one depth from a former
    answer's state.
    """

    def __init__(
        self,
        solver,
        shape,
        direction,
        stiffness,
        tolerance,
        max_updates,
        max_step,
        friction: float = 0.0,
    ):
        if not 0 < tolerance < 1:
            raise ValueError(f"tolerance is a share of the depth in (0, 1), got {tolerance!r}")
        if direction is None and getattr(shape, "path", None) is None:
            raise ValueError("a direction is needed (only a mesh with a path closes without one)")
        self.direction = None if direction is None else unit(direction)
        self.solver, self.shape = solver, shape
        self.options = (tolerance, max_updates, max_step)
        self.contact = Contact(solver, shape, stiffness or default_stiffness(solver))
        self.friction = Friction(self.contact, friction) if friction else None

    def __enter__(self) -> "Pressing":
        self.solver.potentials.append(self.contact)
        if self.friction is not None:
            self.solver.potentials.append(self.friction)
        self.kept = self.solver.options
        self.solver.options = replace(
            self.kept,
            **{k: max(v, getattr(self.kept, k)) for k, v in PATIENCE.items()},
        )
        return self

    def __exit__(self, *exc) -> None:
        self.solver.potentials.remove(self.contact)
        if self.friction is not None:
            self.solver.potentials.remove(self.friction)
        self.solver.options = self.kept

    def to(self, depth: float, start: Pressed | None) -> Pressed:
        """The answer at ``depth`` (m), marching from ``start`` (rest when ``None``)."""
        solver, contact = self.solver, self.contact
        t0 = time.perf_counter()
        if start is None:
            u, done = np.zeros((solver.n_all, 3)), 0.0
            contact.multipliers[:] = 0.0
        else:
            u, done = start.state, start.depth
            contact.multipliers = start.multipliers.copy()
        res = _march(
            solver,
            contact,
            self.shape,
            self.direction,
            u,
            done,
            depth,
            *self.options,
            friction=self.friction,
        )
        if not res["ok"]:
            reason = res["reason"] + f" (residual {res.get('residual', float('nan')):.2e})"
            return Pressed(False, reason, depth, iterations=res["iterations"])
        return self.answer(res["u"], depth, res, t0)

    def answer(self, u: np.ndarray, depth: float, res: dict, t0: float) -> Pressed:
        """The answer at state ``u`` with the object at ``depth`` (m), solved as ``res`` says
        (``iterations``, ``updates``, ``penetration``) since ``time.perf_counter()`` was ``t0``.
        """
        seconds = time.perf_counter() - t0
        return _answer(
            self.solver, self.contact, u, depth, self.direction, res, seconds, self.friction
        )


def _march(
    solver,
    contact,
    shape,
    direction,
    u,
    start,
    depth,
    tolerance,
    max_updates,
    max_step,
    friction=None,
) -> dict:
    """From ``u`` at depth ``start`` to ``depth`` (deeper or shallower) in steps of at most
    ``max_step``, halving the step when one fails; ``friction`` (a :class:`~fem.friction.
    Friction`) is lagged at each step's start.
    """
    sign = 1.0 if depth >= start else -1.0
    s, step, iters, updates, substeps, res = start, abs(depth - start), 0, 0, 0, None
    while sign * (depth - s) > 0 or res is None:
        step = min(step, abs(depth - s), max_step)
        last = step >= abs(depth - s) * (1 - 1e-12)
        to = depth if last else s + sign * step
        contact.shape = shape.pushed(to, direction)
        keep = contact.multipliers.copy()
        if friction is not None:
            x = contact.rest + u[contact.nodes]
            friction.begin(u, motion(shape, direction, x, to - s))
        res = relax(solver, contact, u, tolerance * to, max_updates, not last, friction)
        iters += res["iterations"]
        updates += res.get("updates", 0)
        if res["ok"]:
            u, s = res["u"], to
            continue
        contact.multipliers = keep
        if substeps >= solver.options.max_substeps:
            return {**res, "iterations": iters}
        substeps += 1
        step /= 2
    return {**res, "u": u, "iterations": iters, "updates": updates}


def _answer(solver, contact, u, depth, direction, res, seconds, friction=None) -> Pressed:
    answers = solver.answers  # the part the answer is given on
    detF, compression = solver.measures(u)
    checked = solver.distrust(detF, compression)
    nodal = np.zeros(solver.n_all)  # each skin node's contact force, N
    nodal[contact.nodes] = contact.weights * contact.multipliers
    pressure = answers.pressure(nodal)
    along = nodal.copy()
    if direction is not None:
        along[contact.nodes] *= contact._normals @ direction
    push = answers.pressure(along)  # the reaction's density: sums to it
    rubbed = np.zeros(3) if friction is None else friction.force(u)
    force = contact.force() + rubbed
    total = float(np.sum(contact.weights * contact.multipliers))
    reaction = total if direction is None else float(-force @ direction)
    common = dict(iterations=res["iterations"], updates=res["updates"], time=seconds)
    if checked:
        return Pressed(False, checked, depth, **common)
    return Pressed(
        True,
        "",
        depth,
        displacement=answers.displacement(u),
        state=u,
        reaction=reaction,
        total=total,
        force=force,
        friction=rubbed,
        pressure=pressure,
        push=push,
        area=float(answers.part.vertex_areas[pressure > 0].sum()),
        penetration=res["penetration"],
        min_det_F=detF,
        compression=compression,
        multipliers=contact.multipliers.copy(),
        **common,
    )
