"""Rigid objects pressed into the tissue: the contact's shapes, its potential, and the FEM's
answers against the closed forms of :mod:`fem.verification`.
"""

from dataclasses import replace
from types import SimpleNamespace

import numpy as np
import pytest
import trimesh

import fem.contact
from fem.contact import RTOL, UZAWA_RTOL, Contact, Pressing, press, relax
from fem.material import NeoHookean
from fem.shapes import Punch, Sphere, Surface
from fem.solver import Solver, SolverOptions
from fem.verification import dimitriadis_force, hayes_kappa, hertz_force, punch_slab, quarter_slab


def _kappa(solver, a, h, nu, depth=0.01):
    """The punch's F / (2 E* a delta) pressed ``depth`` x h deep, over Hayes et al.'s kappa."""
    (r,) = press(solver, Punch([0, 0, 0], [0, 0, -1], a), [0, 0, -1], [depth * h])
    assert r.ok, r.reason
    kappa = 4 * r.reaction / (2 * 1000.0 / (1 - nu**2) * a * depth * h)  # a quarter punch
    return kappa / hayes_kappa(a / h, nu)


def test_the_contact_potential_is_consistent():
    """Its gradient is its energy's, its Hessian its gradient's (finite differences; a flat
    punch's faces have no curvature term to leave out).
    """
    solver, a, h = punch_slab(2.0, spacing=0.25, order=1)
    c = Contact(solver, Punch([0, 0, 1e-4], [0, 0, -1], a), 1e6)
    c.multipliers[:] = 5.0
    rng = np.random.default_rng(0)
    u = rng.normal(0, 2e-4, (solver.n_all, 3))
    d = rng.normal(0, 1, (solver.n_all, 3))
    e = 1e-8
    fd = (c.energy(u + e * d) - c.energy(u - e * d)) / (2 * e)
    assert fd == pytest.approx(np.vdot(c.gradient(u), d), rel=1e-5)
    rows, cols, vals = c.hessian(u)
    Hd = np.bincount(rows, vals * d.ravel()[cols], minlength=d.size)
    fd = (c.gradient(u + e * d) - c.gradient(u - e * d)).ravel() / (2 * e)
    np.testing.assert_allclose(Hd, fd, atol=1e-6 * np.abs(fd).max())


def test_the_object_s_distance_is_measured_once_a_state():
    """The residual, the tangent and the energy at one state share one distance; a new state
    or a moved object measures again, with the same answers as measured afresh.
    """
    solver, a, h = punch_slab(2.0, spacing=0.25, order=1)
    punch = Punch([0, 0, 1e-4], [0, 0, -1], a)
    calls = []

    class Counted:
        def __init__(self, shape):
            self.shape = shape

        def distance(self, x):
            calls.append(x.copy())
            return self.shape.distance(x)

    c = Contact(solver, Counted(punch), 1e6)
    c.multipliers[:] = 5.0
    u = np.random.default_rng(0).normal(0, 2e-4, (solver.n_all, 3))
    g, H, E = c.gradient(u), c.hessian(u), c.energy(u)
    assert len(calls) == 1
    v = u.copy()
    v[c.nodes[0], 2] += 1e-6
    c.gradient(v)
    assert len(calls) == 2
    c.shape = Counted(punch)  # the object moved (a new shape): measured again
    np.testing.assert_array_equal(c.gradient(u), g)
    assert len(calls) == 3 and c.energy(u) == E
    fresh = Contact(solver, punch, 1e6)
    fresh.multipliers[:] = 5.0
    np.testing.assert_array_equal(fresh.gradient(u), g)
    for got, want in zip(c.hessian(u), H):
        np.testing.assert_array_equal(got, want)
    with pytest.raises(ValueError, match="read-only"):
        c._distance(u)[1][0] = 0.0  # a kept answer cannot be changed by a caller


def test_the_contact_potential_s_terms_in_the_object_s_depth_are_its_derivatives():
    """Force control in one Newton system differentiates the potential in the object's depth
    too: the reaction is the energy's derivative, ``c`` the reaction's and ``b`` the
    gradient's (finite differences, the punch moved; a flat face has no curvature term).
    """
    solver, a, h = punch_slab(2.0, spacing=0.25, order=1)
    punch, e = Punch([0, 0, 1e-4], [0, 0, -1], a), np.array([0.0, 0.0, -1.0])
    c = Contact(solver, punch, 1e6)
    c.multipliers[:] = 5.0
    u = np.random.default_rng(0).normal(0, 2e-4, (solver.n_all, 3))
    b, stiff, reaction, scale = c.coupling(u, e)
    step = 1e-9

    def at(depth):
        c.shape = punch.pushed(depth, e)
        return c.energy(u), c.gradient(u), c.coupling(u, e)[2]

    (E1, g1, R1), (E0, g0, R0) = at(step), at(-step)
    assert reaction > 0 and reaction == pytest.approx((E1 - E0) / (2 * step), rel=1e-5)
    assert stiff == pytest.approx((R1 - R0) / (2 * step), rel=1e-5)
    np.testing.assert_allclose(b, (g1 - g0) / (2 * step), atol=1e-5 * np.abs(b).max())
    assert scale == pytest.approx(np.linalg.norm(g0 + g1) / 2, rel=1e-6)


def test_a_flat_punch_on_a_bonded_layer_meets_hayes():
    """A rigid flat punch of radius a = 2 h pushed 1 % of h into a bonded layer (nu = 0.45,
    rings every 0.05 a across the rim: -1.3 %; 0.07 a: -2.8 %; 0.04 a: -0.5 %),
    displacement controlled: F / (2 E* a delta) within 3 % of Hayes et al.'s kappa; the
    supports carry the reaction; the pressure is zero outside the punch, the contact area the
    punch's face.
    """
    solver, a, h = punch_slab(2.0)
    delta = 0.01 * h
    (r,) = press(solver, Punch([0, 0, 0], [0, 0, -1], a), [0, 0, -1], [delta])
    assert r.ok, r.reason
    Es = 1000.0 / (1 - 0.45**2)
    kappa = 4 * r.reaction / (2 * Es * a * delta)  # a quarter of the punch
    assert kappa == pytest.approx(hayes_kappa(2.0, 0.45), rel=0.03)
    assert r.penetration <= 2e-3 * delta
    radius = np.linalg.norm(solver.mesh.part.vertices[:, :2], axis=1)
    assert r.pressure[radius > a * 1.0001].max() == 0.0
    s = 0.05 * a  # the rings' spacing at the rim: the area ends within one of it
    assert np.pi * (a - s) ** 2 < 4 * r.area < np.pi * (a + s) ** 2
    held = solver.residual(r.state, np.zeros_like(r.state))  # the tissue's own forces
    held.reshape(-1)[solver.free] = 0.0  # what the supports (base, far rim) carry
    assert held[:, 2].sum() == pytest.approx(r.reaction, rel=1e-6)


@pytest.mark.slow
@pytest.mark.parametrize("a_over_h", [0.5, 1.0, 2.0])
def test_hayes_on_a_finerpunch_slab(a_over_h):
    """The verification's full version: rings every a / 25 across the rim: +0.5, -0.2, -0.7 %
    (52-133 s each).
    """
    solver, a, h = punch_slab(a_over_h, spacing=0.04, first_layer=0.001, ratio=1.3)
    delta = 0.01 * h
    (r,) = press(solver, Punch([0, 0, 0], [0, 0, -1], a), [0, 0, -1], [delta])
    assert r.ok, r.reason
    kappa = 4 * r.reaction / (2 * 1000.0 / (1 - 0.45**2) * a * delta)
    assert kappa == pytest.approx(hayes_kappa(a_over_h, 0.45), rel=0.03)


def test_depths_must_rise_and_a_failure_skips_the_rest():
    solver, a, h = punch_slab(2.0, spacing=0.25, order=1)
    with pytest.raises(ValueError, match="depths must rise strictly"):
        press(solver, Punch([0, 0, 0], [0, 0, -1], a), [0, 0, -1], [2e-4, 1e-4])
    out = press(solver, Punch([0, 0, 0], [0, 0, -1], a), [0, 0, -1], [1e-4, 1.2 * h, 1.3 * h])
    assert out[0].ok and not out[1].ok and out[1].displacement is None
    assert out[2].reason.startswith("skipped")
    assert not solver.potentials  # the contact leaves with the call


def test_a_press_answered_from_a_deeper_state_is_the_same_answer():
    """The tissue is elastic and the contact frictionless: marching back from a deeper answer
    (what force control does when it overshoots) lands where pressing from rest does.
    """
    solver, a, h = punch_slab(2.0, spacing=0.25, order=1)
    punch = Punch([0, 0, 0], [0, 0, -1], a)
    shallow, deep = press(solver, punch, [0, 0, -1], [0.006 * h, 0.01 * h])
    assert shallow.ok and deep.ok, (shallow.reason, deep.reason)
    with Pressing(solver, punch, np.array([0, 0, -1.0]), None, 2e-3, 20, 0.001) as go:
        back = go.to(0.006 * h, deep)
    assert back.ok, back.reason
    assert back.reaction == pytest.approx(shallow.reaction, rel=2e-3)
    gap = np.abs(back.displacement - shallow.displacement).max()
    assert gap <= 2e-3 * np.abs(shallow.displacement).max()


def test_nearly_incompressible_layers_lock_with_linear_elements_not_quadratic_ones():
    """The locking test: the punch on a layer of nu = 0.49. Linear tetrahedra lock (kappa
    36 % too high here, 415 % at nu = 0.499); quadratic ones stay within 3 % of Hayes (-1.7 %;
    -0.1 % at nu = 0.499), which is why every tissue is meshed with them.
    """
    kappa = hayes_kappa(2.0, 0.49)
    found = {}
    for order in (1, 2):
        solver, a, h = punch_slab(2.0, spacing=0.07, order=order, nu=0.49)
        (r,) = press(solver, Punch([0, 0, 0], [0, 0, -1], a), [0, 0, -1], [0.01 * h])
        assert r.ok, r.reason
        found[order] = 4 * r.reaction / (2 * 1000.0 / (1 - 0.49**2) * a * 0.01 * h) / kappa
    assert found[1] > 1.2 and found[2] == pytest.approx(1.0, abs=0.03)


@pytest.mark.slow
def test_quadratic_displacement_elements_drift_stiff_as_the_layer_nears_incompressibility():
    """Without mean dilatation the quadratic elements start to lock: the punch at nu =
    0.49999 (K / mu 50000) comes out 1.7 % stiffer than Hayes where nu = 0.45 gives -2.8 %
    (+0.8 % at 0.4999; at 0.499999 the solve fails; 85 s).
    """
    nu = 0.49999
    solver, a, h = punch_slab(2.0, spacing=0.07, order=2, nu=nu)
    assert _kappa(solver, a, h, nu) == pytest.approx(1.0, abs=0.03)


def test_mean_dilatation_frees_quadratic_elements_of_locking():
    """The locking test of the tissue laws (mean dilatation, one pressure per element): the
    punch's error against Hayes stays the same from nu = 0.45 to 0.49999 (-6.5 % on this
    coarse slab, which the slow version refines), where the quadratic displacement elements
    alone drift from -4.3 % to +1.1 % and take ten times as long.
    """
    errors = [
        _kappa(*punch_slab(2.0, spacing=0.12, nu=nu, volume="mean"), nu) for nu in (0.45, 0.49999)
    ]
    assert errors[0] == pytest.approx(errors[1], abs=0.003)
    assert errors[1] == pytest.approx(1.0, abs=0.07)


@pytest.mark.slow
def test_mean_dilatation_meets_hayes_at_any_bulk_modulus():
    """The full version: rings every a / 20 across the rim, within 3 % of Hayes at nu = 0.45
    (-2.4 %) and 0.499999 (K / mu 500000) alike (about 20 s each).
    """
    for nu in (0.45, 0.499999):
        assert _kappa(*punch_slab(2.0, spacing=0.05, nu=nu, volume="mean"), nu) == pytest.approx(
            1.0, abs=0.03
        )


def _sphere_on_layer(h, chis, spacing, first_layer, ratio, nu=0.49, R=0.01):
    """A rigid sphere of radius R pressed into a bonded layer of thickness h to each contact
    radius ratio chi = (R delta)^(1/2) / h: the FEM's forces (the quarter's, times four).
    """
    depths = [(c * h) ** 2 / R for c in chis]
    a = np.sqrt(R * depths[-1])
    part, mesh, fixed = quarter_slab(h, a + 5 * h, a, spacing * a, first_layer, ratio)
    solver = Solver(mesh, NeoHookean(1000.0, nu), fixed, SolverOptions(rims="free"), order=2)
    out = press(solver, Sphere([0, 0, R], R), [0, 0, -1], depths)
    assert all(r.ok for r in out), [r.reason for r in out]
    return depths, [4 * r.reaction for r in out]


@pytest.mark.slow
def test_a_sphere_on_a_bonded_layer_meets_dimitriadis():
    """A 10 mm sphere on a 5 mm layer (nu = 0.49) to contact radii of 0.1-0.3 h: within 5 % of
    Dimitriadis et al.'s bonded-layer force (+0.3, -1.2, -0.5 %; about 3 min), where Hertz's
    half-space is 15-49 % too soft.
    """
    h, R = 0.005, 0.01
    depths, forces = _sphere_on_layer(h, [0.1, 0.2, 0.3], 0.08, h / 20, 1.3)
    for d, f in zip(depths, forces):
        assert f == pytest.approx(dimitriadis_force(1000.0, R, d, h), rel=0.05)
        assert f > 1.1 * hertz_force(1000.0, 0.49, R, d)


@pytest.mark.slow
def test_a_sphere_on_a_thick_layer_meets_hertz():
    """A 10 mm sphere pushed 9 um into a 10 mm layer (contact radius 0.03 h, nu = 0.49): within
    5 % of Hertz's half-space force (+3.9 %, of which Dimitriadis' thickness correction is
    +3.5 %; about 3 min).
    """
    h, R = 0.01, 0.01
    (d,), (f,) = _sphere_on_layer(h, [0.03], 0.1, 0.0001, 1.4)
    assert f == pytest.approx(hertz_force(1000.0, 0.49, R, d), rel=0.05)


def test_a_mesh_presses_as_the_shape_it_approximates():
    """An icosphere (radius 10 mm, 10242 vertices, rounded by 0.5 mm) on a bonded layer presses
    as the exact sphere of 10.5 mm (within 2 %), and the same mesh closing along a path that
    moves every vertex straight down presses exactly as when it is moved down.
    """
    h, R, rounding = 0.005, 0.01, 5e-4
    depth = (0.3 * h) ** 2 / R
    a = np.sqrt(R * depth)
    part, mesh, fixed = quarter_slab(h, a + 3 * h, a, 0.25 * a, h / 10, 1.5)
    solver = Solver(mesh, NeoHookean(1000.0, 0.45), fixed, SolverOptions(rims="free"), order=2)
    ball = trimesh.creation.icosphere(subdivisions=5, radius=R)
    centre = np.array([0, 0, R + rounding])
    surface = Surface(ball.vertices + centre, ball.faces, rounding=rounding)
    down = np.array([0.0, 0, -1])
    (exact,) = press(solver, Sphere(centre, R + rounding), down, [depth])
    (meshed,) = press(solver, surface, down, [depth])
    closing = replace(surface, path=np.tile(down, (len(ball.vertices), 1)))
    (closed,) = press(solver, closing, None, [depth])
    assert exact.ok and meshed.ok and closed.ok, (exact.reason, meshed.reason, closed.reason)
    assert meshed.reaction == pytest.approx(exact.reaction, rel=0.02)
    assert closed.total == pytest.approx(meshed.total, rel=1e-6)  # the solves' own tolerance
    assert closed.reaction == closed.total
    assert meshed.total == pytest.approx(meshed.reaction, rel=0.01)  # nearly all along the push
    # the state's own measures: the skin under the ball moves in by the depth, and the
    # tissue under it loses volume (nu = 0.45) without inverting
    assert meshed.compression == pytest.approx(depth / h, rel=0.02)
    assert 0.9 < meshed.min_det_F < 1.0
    # the pressure map on the part's vertices keeps the whole contact force
    carried = float(np.sum(meshed.pressure * part.vertex_areas))
    assert carried == pytest.approx(meshed.total, rel=1e-9)
    with pytest.raises(ValueError, match="a direction is needed"):
        press(solver, surface, None, [depth])
    assert solver.options.stagnation == SolverOptions().stagnation  # patience only while pressing


def test_uzawa_solves_loosely_until_the_multipliers_settle_then_checks_the_answer():
    """While the multipliers still move, each equilibrium is solved to the loose residual and
    not checked for stability; once an update meets the tolerances, one more solve to the
    answer's residual is checked, told that a loose solve stepped without the pressure
    stiffness, and judged again. A step on the way is one loose, unchecked solve.
    """
    lefts = iter([0.5, 0.01, 1e-4, 1e-5])

    class Stub:
        held_inside = 0.0

        def update(self, u):
            return 0.0, next(lefts)

    calls = []

    def solve(u, rtol, floor, check, definite):
        calls.append((rtol, check, definite))
        return {"ok": True, "u": u, "iterations": 2, "definite": len(calls) == 1 and not check}

    solver = SimpleNamespace(options=SimpleNamespace(rtol=1e-8))
    out = relax(solver, Stub(), np.zeros((3, 3)), 1e-6, 20, solve=solve)
    assert out["ok"] and out["updates"] == 4 and out["iterations"] == 8
    assert calls == [(UZAWA_RTOL, False, False)] + [(UZAWA_RTOL, False, True)] * 2 + [
        (RTOL, True, True)
    ]
    lefts, calls[:] = iter([0.5]), []
    out = relax(solver, Stub(), np.zeros((3, 3)), 1e-6, 20, on_the_way=True, solve=solve)
    assert out["ok"] and calls == [(UZAWA_RTOL, False, False)]
    lefts, calls[:] = iter([0.5, 1e-4]), []
    strict = SimpleNamespace(options=SimpleNamespace(rtol=UZAWA_RTOL))  # nothing looser
    assert relax(strict, Stub(), np.zeros((3, 3)), 1e-6, 20, solve=solve)["ok"]
    assert calls == [(UZAWA_RTOL, True, False), (UZAWA_RTOL, True, False)]


def test_a_press_solved_loosely_on_the_way_is_the_press_solved_tightly_throughout():
    """A ball pressed 15 % of a slab's depth with Uzawa's iteration solved inexactly (the
    default) and exactly (every solve to the answer's residual): the same reaction and
    displacement within the solver's tolerances, in fewer Newton iterations (7 against 10).
    """
    solver, a, h = punch_slab(2.0, spacing=0.25)
    ball = Sphere([0.0, 0.0, 0.5 * a], 0.5 * a)
    e = [0.0, 0.0, -1.0]
    (loose,) = press(solver, ball, e, [0.15 * h])
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(fem.contact, "UZAWA_RTOL", RTOL)
        (tight,) = press(solver, ball, e, [0.15 * h])
    assert loose.ok and tight.ok, (loose.reason, tight.reason)
    assert loose.reaction == pytest.approx(tight.reaction, rel=1e-4)
    gap = np.abs(loose.displacement - tight.displacement).max()
    assert gap <= 1e-4 * np.abs(tight.displacement).max()
    assert loose.iterations < tight.iterations, (loose.iterations, tight.iterations)
