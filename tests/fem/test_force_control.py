"""Force control: the depth at which a pressed object carries a force, found within a
tolerance, its search shortened past failures and stopped where no depth gets past one.
"""

import numpy as np
import pytest

import fem.force_control
from fem.contact import Pressed, Pressing, press
from fem.force_control import _aim, press_to_force
from fem.limits import Limits
from fem.material import Layered
from fem.shapes import Punch, Sphere
from fem.solver import Solver
from fem.verification import punch_slab


def test_force_control_finds_the_depth_that_carries_a_force():
    """The search: a target reaction met within 1 % (the slab's response is nearly linear
    here: the depth found lies within 2 % of the one that gave that force).
    """
    solver, a, h = punch_slab(2.0, spacing=0.12)
    punch = Punch([0, 0, 0], [0, 0, -1], a)
    (known,) = press(solver, punch, [0, 0, -1], [0.008 * h])
    assert known.ok, known.reason
    found = press_to_force(solver, punch, [0, 0, -1], known.reaction, step=0.003 * h, coupled=False)
    assert found.ok, found.reason
    assert found.reaction == pytest.approx(known.reaction, rel=0.01)
    assert found.depth == pytest.approx(0.008 * h, rel=0.02)


@pytest.mark.slow
def test_a_force_past_what_the_gel_carries_fails_where_it_stops():
    """1 kN on the gel slab: the search closes in on where the gel stops answering (its
    trust bound, nine tries) and says how far it got.
    """
    solver, a, h = punch_slab(2.0, spacing=0.12)
    punch = Punch([0, 0, 0], [0, 0, -1], a)
    failed = press_to_force(solver, punch, [0, 0, -1], 1e3, step=0.2 * h)
    assert not failed.ok and failed.reason.startswith("cannot carry 1000 N: not trusted")
    assert "after 0.4" in failed.reason and failed.displacement is None


@pytest.mark.parametrize("shape", ["ball", "rounded punch"])
def test_force_control_in_one_newton_system_meets_the_force_where_the_depth_press_would(
    monkeypatch, shape
):
    """The depth solved with the displacement (the reaction's equation in the Newton system):
    the force met to the solver's tolerance in one march, no try after the first touch, and
    the answer the same as a press to the depth it found (a smooth object: no other
    equilibrium on the way), the second force from the first's answer.
    """
    solver, a, h = punch_slab(2.0, spacing=0.25)
    e = np.array([0.0, 0.0, -1.0])
    if shape == "ball":  # Hertz: 1e-4 N at some 0.07 mm, 4e-4 N at 0.18 mm
        obj, forces = Sphere([0.0, 0.0, 0.5 * a], 0.5 * a), [1e-4, 4e-4]
    else:  # a flat punch on the layer: about 50 N/m
        obj, forces = Punch([0.0, 0.0, 0.0], e, a, rounding=0.2 * a), [3e-3, 8e-3]
    tries, to = [], Pressing.to

    def counted(self, depth, start):
        tries.append(depth)
        return to(self, depth, start)

    monkeypatch.setattr(Pressing, "to", counted)
    step = 0.002 * h
    answers = [press_to_force(solver, obj, e, forces[0], step=step)]
    answers.append(press_to_force(solver, obj, e, forces[1], step=step, start=answers[0]))
    assert len(tries) == 1  # the first touch, a step from rest
    monkeypatch.setattr(Pressing, "to", to)
    for f, got in zip(forces, answers):
        assert got.ok, got.reason
        assert got.reaction == pytest.approx(f, rel=1e-6)
        (same,) = press(solver, obj, e, [got.depth])
        assert same.reaction == pytest.approx(f, rel=1e-4)
        peak = np.abs(same.displacement).max()
        assert np.abs(got.displacement - same.displacement).max() < 1e-4 * peak
    searched = press_to_force(solver, obj, e, forces[1], step=step, coupled=False)
    assert searched.depth == pytest.approx(answers[1].depth, rel=0.01)


def test_where_the_one_system_stalls_the_search_starts_at_the_depth_it_reached(monkeypatch):
    """A Newton system that stagnates (a contact node on the edge of touching) still says how
    deep it got: the search's first try is a press to that depth, which carries the force
    within the tolerance there.
    """
    solver, a, h = punch_slab(2.0, spacing=0.25)
    e = np.array([0.0, 0.0, -1.0])
    ball = Sphere([0.0, 0.0, 0.5 * a], 0.5 * a)
    (known,) = press(solver, ball, e, [0.012 * h])
    reached = 0.997 * known.depth

    def stalled(go, u, depth, force, rtol, floor=0.0, check=True, definite=False):
        return {"ok": False, "reason": "stagnated (test)", "iterations": 10, "depth": reached}

    tries, to = [], Pressing.to

    def counted(self, depth, start):
        tries.append(depth)
        return to(self, depth, start)

    monkeypatch.setattr(fem.force_control, "_newton_on_depth", stalled)
    monkeypatch.setattr(Pressing, "to", counted)
    found = press_to_force(solver, ball, e, known.reaction, step=0.002 * h)
    assert found.ok, found.reason
    assert found.reaction == pytest.approx(known.reaction, rel=0.01)
    assert tries == [0.002 * h, reached]  # the first touch, then the depth reached


def test_force_control_aims_by_the_power_law_through_its_last_two_answers():
    """On an exact power law F = c d^p (p in [1, 4]) the aim is the depth itself; from rest,
    Hertz's exponent 1.5; a steeper law is aimed at as p = 4.
    """
    for p in (1.0, 1.5, 2.7):
        a, b = (Pressed(True, "", d, reaction=3.0 * d**p) for d in (1e-3, 2e-3))
        assert _aim(a, b, 3.0 * 5e-3**p) == pytest.approx(5e-3, rel=1e-9)
    rest, b = Pressed(True, "", 0.0, reaction=0.0), Pressed(True, "", 1e-3, reaction=0.2)
    assert _aim(rest, b, 0.2 * 8**1.5) == pytest.approx(8e-3, rel=1e-9)
    a, b = (Pressed(True, "", d, reaction=d**6) for d in (1.0, 2.0))
    untouched = Pressed(True, "", 1e-3, reaction=0.0)
    assert _aim(rest, untouched, 1.0) == np.inf  # not touched yet: as far as the reach allows
    assert _aim(a, b, 3.0**6) == pytest.approx(2.0 * (3**6 / 2**6) ** 0.25)


def test_force_control_steps_back_inside_the_trust_bounds():
    """A tissue trusted to twice the target's compression: force control's first step
    lands past it, is shortened, and meets the force; a force that needs more is failed with
    the bound named.
    """
    solver, a, h = punch_slab(2.0, spacing=0.25)
    punch = Punch([0, 0, 0], [0, 0, -1], a)
    (known,) = press(solver, punch, [0, 0, -1], [0.008 * h])
    assert known.ok, known.reason
    layer = np.zeros(len(solver.mesh.tets), dtype=int)
    limits = Limits(0.0, 2 * known.compression, "test")
    bounded = Solver(
        solver.mesh,
        Layered((solver.material,), layer, limits),
        options=solver.options,
        order=2,
    )
    found = press_to_force(bounded, punch, [0, 0, -1], known.reaction, step=0.025 * h)
    assert found.ok, found.reason
    assert found.reaction == pytest.approx(known.reaction, rel=0.01)
    failed = press_to_force(bounded, punch, [0, 0, -1], 3 * known.reaction, step=0.003 * h)
    assert not failed.ok and "not trusted" in failed.reason and "trusted up to" in failed.reason


def test_force_control_shortens_a_try_whose_march_fails(monkeypatch):
    """A march that cannot go further than 1.5 steps past its start (as a closing grip's line
    search may stall): force control halves the failed try, aims no further than that, and
    still meets the force.
    """
    solver, a, h = punch_slab(2.0, spacing=0.25, order=1)
    punch = Punch([0, 0, 0], [0, 0, -1], a)
    (known,) = press(solver, punch, [0, 0, -1], [0.008 * h])
    assert known.ok, known.reason
    step, to, tries = 0.001 * h, Pressing.to, []

    def stalling(self, depth, start):
        tries.append(depth)
        if abs(depth - (start.depth if start else 0.0)) > 1.5 * step:
            return Pressed(False, "line search failed (test)", depth)
        return to(self, depth, start)

    monkeypatch.setattr(Pressing, "to", stalling)
    found = press_to_force(solver, punch, [0, 0, -1], known.reaction, step=step, coupled=False)
    assert found.ok, found.reason
    assert found.reaction == pytest.approx(known.reaction, rel=0.01)
    assert any(t > 1.5 * step for t in tries)  # the aim first reached further, and was shortened


def test_force_control_says_when_the_force_falls_as_the_object_goes_deeper(monkeypatch):
    """A grip whose fingers slip round the limb squeezes less as it closes further: force
    control stops there and says so, instead of chasing the force through the whole tissue.
    """
    solver, a, h = punch_slab(2.0, spacing=0.25, order=1)

    def slipping(self, depth, start):
        squeeze = 1.0 * depth / h if depth < 0.3 * h else 0.3 - 0.5 * (depth / h - 0.3)
        return Pressed(True, "", depth, reaction=squeeze)

    monkeypatch.setattr(Pressing, "to", slipping)
    punch = Punch([0, 0, 0], [0, 0, -1], a)
    failed = press_to_force(solver, punch, [0, 0, -1], 0.5, step=0.1 * h, coupled=False)
    assert not failed.ok and failed.displacement is None
    assert "the force falls as the object goes deeper" in failed.reason


def test_force_control_steps_past_a_depth_where_the_march_stalls(monkeypatch):
    """A Newton solve that stalls at one band of depths only (as a contact whose nodes come and
    go may): force control closes in on the band, then tries once a step that lands past it,
    and meets the force beyond; a band it cannot step past still ends the search, saying where.
    """
    solver, a, h = punch_slab(2.0, spacing=0.25, order=1)
    band, tries = (0.245 * h, 0.255 * h), []

    def stalling(self, depth, start):
        tries.append(depth)
        if band[0] <= depth <= band[1]:
            return Pressed(False, "line search failed to lower the energy (test)", depth)
        return Pressed(True, "", depth, reaction=(depth / h) ** 1.5)

    monkeypatch.setattr(Pressing, "to", stalling)
    punch = Punch([0, 0, 0], [0, 0, -1], a)
    found = press_to_force(solver, punch, [0, 0, -1], 0.4**1.5, step=0.05 * h, coupled=False)
    assert found.ok, found.reason
    assert found.depth == pytest.approx(0.4 * h, rel=0.01)
    assert any(band[0] <= t <= band[1] for t in tries)  # it met the band on the way

    band = (0.245 * h, 0.5 * h)  # too wide to step past
    failed = press_to_force(solver, punch, [0, 0, -1], 0.25, step=0.05 * h, coupled=False)
    assert not failed.ok and failed.reason.startswith("cannot carry 0.25 N: line search failed")
    stalled = float(failed.reason.split("at depth ")[1].split(" mm")[0])
    assert 0.245 * h <= 1e-3 * stalled <= 0.25 * h  # where it stalled, not where it jumped


def test_forces_in_turn_each_from_the_last_and_the_rest_skipped_after_a_failure(monkeypatch):

    starts, tolerances = [], []

    def fake(solver, shape, direction, force, rtol=0.01, start=None, friction=0.0, coupled=True):
        starts.append(None if start is None else start.reaction)
        tolerances.append(rtol)
        if force > 4:
            return Pressed(False, f"cannot carry {force:g} N: not trusted", 0.005)
        return Pressed(True, "", 1e-3 * force, reaction=force)

    monkeypatch.setattr(fem.force_control, "press_to_force", fake)
    seen = []
    out = fem.force_control.press_to_forces(
        None, None, None, [1.0, 2.0, 5.0, 10.0], lambda f, a: seen.append((f, a.ok)), rtol=0.2
    )
    assert starts == [None, 1.0, 2.0]  # each from the last answer; none after the failure
    assert tolerances == [0.2] * 3  # each force met within the tolerance asked
    assert [a.ok for a in out] == [True, True, False, False]
    assert out[3].reason == "skipped: 5 N failed" and seen == [
        (1.0, True),
        (2.0, True),
        (5.0, False),
        (10.0, False),
    ]


def test_an_object_over_the_held_rim_fails_at_once_saying_so():
    """A ball over the cut end of a tube, which the FEM holds in place: the skin there cannot
    give way, so no depth carries the force; force control stops at its first try and names
    the rim, instead of updating multipliers that cannot push a held node out.
    """
    from fem.objects import placed
    from fem.simulate import tissue_mesh
    from fem.solver import Solver
    from stmpl.body.primitives import tube

    part = tube(radius=0.04, length=0.12, n_around=16, n_along=6)
    at = int(part.rims[0][0])
    mesh, mat = tissue_mesh(
        part, np.full(part.n_vertices, 0.0075), {"subdivisions": 0, "layers": 2}, "paper", None
    )
    solver = Solver(mesh, mat, order=1)
    shape, direction = placed(part, "press_sphere", {"at": at, "radius": 0.008})
    failed = press_to_force(solver, shape, direction, 0.1)
    assert not failed.ok and failed.displacement is None
    assert failed.reason.startswith("cannot carry 0.1 N: the object presses the part's held rim")
    assert failed.iterations < 40  # one try, not a search


@pytest.mark.parametrize("friction", [None, 0.5])
def test_the_bracket_s_tries_march_from_below_where_friction_makes_the_answer_path_dependent(
    friction,
):
    """Between an answer below the force and one above, a try without friction marches from
    the nearer one; with friction always from the one below (or from rest): the object closes
    on the skin and never backs off it, so the answer is the loading path's.
    """

    class Go:  # a press that stiffens past Hertz's law, each try's start recorded
        def __init__(self):
            self.friction, self.starts = friction, []

        def to(self, depth, start):
            self.starts.append((depth, None if start is None else start.depth))
            return Pressed(True, "", depth, reaction=2e4 * depth**1.5 + 4e9 * depth**4)

    for lo_depth in (0.0, 0.001):
        go = Go()
        lo, hi = (go.to(d, None) for d in (lo_depth, 0.004))
        go.starts.clear()
        found = fem.force_control._between(go, 1.5, 1e-6, lo, hi)
        assert found.ok and found.reaction == pytest.approx(1.5, rel=1e-6)
        assert len(go.starts) >= 3
        came_from_above = [d for d, s in go.starts if s is not None and s > d]
        if friction:
            assert not came_from_above
            assert all(s is None or s < d for d, s in go.starts)
        else:
            assert came_from_above  # the shorter march, down from the answer above
